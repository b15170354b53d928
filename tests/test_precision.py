"""bf16 autocast is honoured only where it is fast (lerobot_rnd/precision.py): on a CPU without native bf16 the
network runs in float32, with one warning, and LEROBOT_RND_CPU_BF16 overrides the hardware check."""

import logging

import pytest
import torch

from lerobot_rnd import precision


@pytest.fixture
def cpu_bf16(monkeypatch):
    """Set the hardware check's answer via the override variable (and clear its cache around the test)."""

    def set_fast(fast: bool):
        monkeypatch.setenv(precision.CPU_BF16_ENV, "1" if fast else "0")
        precision.cpu_bf16_is_fast.cache_clear()

    yield set_fast
    precision.cpu_bf16_is_fast.cache_clear()


def _matmul_dtype(ctx) -> torch.dtype:
    a = torch.randn(4, 4)
    with ctx:
        return (a @ a).dtype


def test_cpu_without_native_bf16_runs_float32_and_warns_once(cpu_bf16, caplog, monkeypatch):
    cpu_bf16(False)
    monkeypatch.setattr(precision, "_warned", False)
    with caplog.at_level(logging.WARNING):
        assert _matmul_dtype(precision.bf16_autocast(True, "cpu")) == torch.float32
        assert _matmul_dtype(precision.bf16_autocast(True, "cpu")) == torch.float32
    warnings = [r for r in caplog.records if "autocast_bf16=True is ignored" in r.getMessage()]
    assert len(warnings) == 1 and precision.CPU_BF16_ENV in warnings[0].getMessage()


def test_cpu_with_native_bf16_autocasts(cpu_bf16):
    cpu_bf16(True)
    assert _matmul_dtype(precision.bf16_autocast(True, "cpu")) == torch.bfloat16
    assert _matmul_dtype(precision.bf16_autocast(False, "cpu")) == torch.float32  # off when not asked for


def test_the_hardware_check_agrees_with_onednn_when_not_overridden(monkeypatch):
    monkeypatch.delenv(precision.CPU_BF16_ENV, raising=False)
    precision.cpu_bf16_is_fast.cache_clear()
    try:
        assert precision.cpu_bf16_is_fast() == bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    finally:
        precision.cpu_bf16_is_fast.cache_clear()


def test_the_policy_network_follows_the_check(cpu_bf16):
    """The R&D model's network context (`RnDModel._autocast`) is float32 on a CPU without native bf16 even with
    autocast_bf16=True, and bf16 where the CPU has it."""
    from lerobot_rnd.modeling_rnd import RnDModel

    class Stub:
        config = type("C", (), {"autocast_bf16": True})()

    cpu_bf16(False)
    assert _matmul_dtype(RnDModel._autocast(Stub(), "cpu")) == torch.float32
    cpu_bf16(True)
    assert _matmul_dtype(RnDModel._autocast(Stub(), "cpu")) == torch.bfloat16
