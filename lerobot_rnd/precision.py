"""Where bfloat16 autocast pays: CUDA, and CPUs that run bf16 matmuls natively.

On a CPU without native bf16 (e.g. AVX2 only) oneDNN emulates bf16 and autocast makes a CPU-tier training step
about 19x *slower* (16.7 s against 0.89 s in float32, measured on a 2-core AVX2 EPYC), so `autocast_bf16` is
only honoured where it is fast, with one warning where it is not.
"""

from __future__ import annotations

import logging
import os
from contextlib import nullcontext
from functools import lru_cache

import torch

# LEROBOT_RND_CPU_BF16=1 forces bf16 autocast on any CPU, =0 never; unset: decided by the hardware check.
CPU_BF16_ENV = "LEROBOT_RND_CPU_BF16"


@lru_cache(maxsize=1)
def cpu_bf16_is_fast() -> bool:
    """True when this CPU runs bf16 matmuls natively (oneDNN's check: AVX-512 BW/VL/DQ, AVX-512 bf16 or AMX; on
    Arm, bf16 instructions), so autocast speeds training up instead of emulating bf16."""
    forced = os.environ.get(CPU_BF16_ENV)
    if forced is not None and forced.strip() != "":
        return forced.strip().lower() in ("1", "true", "yes")
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # no oneDNN in this build: judge by the vector ISA torch dispatches to
        return torch.backends.cpu.get_cpu_capability().startswith(("AVX512", "AMX"))


def bf16_autocast_applies(device_type: str) -> bool:
    """Whether `autocast_bf16=True` is honoured on `device_type` ("cuda": always; "cpu": if `cpu_bf16_is_fast()`)."""
    if device_type == "cpu":
        return cpu_bf16_is_fast()
    return device_type == "cuda"


_warned = False


def bf16_autocast(enabled: bool, device_type: str):
    """`torch.autocast(device_type, bfloat16)` when `enabled` and it is fast here, else a no-op context (float32);
    warns once when `enabled` is ignored."""
    global _warned
    if not enabled:
        return nullcontext()
    if not bf16_autocast_applies(device_type):
        if not _warned:
            _warned = True
            logging.warning(
                "autocast_bf16=True is ignored on this %s: it has no native bf16 (torch CPU capability %s), where "
                "bf16 autocast is many times slower than float32. Set %s=1 to force it.",
                device_type, torch.backends.cpu.get_cpu_capability(), CPU_BF16_ENV,
            )  # fmt: skip
        return nullcontext()
    return torch.autocast(device_type=device_type, dtype=torch.bfloat16)
