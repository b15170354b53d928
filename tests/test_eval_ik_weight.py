"""benchmarks/eval_ik_weight.py: the checkpoint copies it evaluates carry the asked IK orientation weight, and it
refuses test seeds and robots without a joint-space action adapter."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
try:
    import eval_ik_weight
finally:
    sys.path.remove(str(REPO / "benchmarks"))


def _checkpoint(tmp_path: Path, adapter: dict) -> Path:
    ckpt = tmp_path / "pretrained_model"
    ckpt.mkdir()
    (ckpt / "config.json").write_text(json.dumps({"type": "rnd", "action_adapter": adapter}))
    (ckpt / "model.safetensors").write_bytes(b"weights")
    return ckpt


def test_the_copy_carries_the_weight_and_the_original_is_untouched(tmp_path):
    from lerobot_rnd import so101
    from lerobot_rnd.action_adapters import ActionAdapter

    ckpt = _checkpoint(tmp_path, so101.so101_action_adapter())
    before = (ckpt / "config.json").read_text()
    copy = eval_ik_weight.with_weight(ckpt, 0.1, tmp_path / "w" / "pretrained_model")
    assert (ckpt / "config.json").read_text() == before
    assert (copy / "model.safetensors").read_bytes() == b"weights"
    spec = json.loads((copy / "config.json").read_text())["action_adapter"]
    assert ActionAdapter.from_dict(spec).ik_orientation_weight == 0.1
    assert ActionAdapter.from_dict(json.loads(before)["action_adapter"]).ik_orientation_weight == 1.0


def test_a_robot_without_joint_space_actions_is_refused(tmp_path):
    ckpt = _checkpoint(tmp_path, {"type": "ee_delta"})
    with pytest.raises(SystemExit, match="joint_positions"):
        eval_ik_weight.with_weight(ckpt, 0.1, tmp_path / "copy")


def test_test_seeds_are_refused(tmp_path, capsys):
    ckpt = _checkpoint(tmp_path, {"type": "joint_positions"})
    with pytest.raises(SystemExit):
        eval_ik_weight.main(["--checkpoint", str(ckpt), "--task", "pick-cube", "--seed", "990", "--episodes", "20",
                             "--work-dir", str(tmp_path / "w"), "--out", str(tmp_path / "o.json")])  # fmt: skip
    assert "test seeds" in capsys.readouterr().err
