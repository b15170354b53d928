"""benchmarks/eval_train_placements.py's demo replay: the recorded actions, replayed from each demo's placement,
must bring the gripper where the recording did (reference: the recorder's own success flags and frame counts,
and MetaWorld's own `obj_to_target`)."""

import json
from pathlib import Path

import pytest

pytest.importorskip("metaworld")

from benchmarks.eval_train_placements import replay_demos, training_placements  # noqa: E402
from lerobot_rnd.sim import record as rec  # noqa: E402
from tests.helpers import gl_available  # noqa: E402

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")


def test_replayed_demos_end_where_the_recording_did(tmp_path):
    root = tmp_path / "reach"
    argv = ["--task", "reach-v3", "--episodes", "2", "--root", str(root), "--repo-id", "local/replay",
            "--image-size", "32", "--seed", "7"]  # fmt: skip
    assert rec.main(argv) == 0
    log = json.loads((root / rec.RECORDING_FILE).read_text())
    kept = sorted((a for a in log["attempts"] if a["success"]), key=lambda a: a["episode_index"])
    assert training_placements(root) == [a["placement"] for a in kept]
    demos = replay_demos(root, "reach-v3")
    assert [d["frames"] for d in demos] == [a["num_frames"] for a in kept]
    for d in demos:
        # the recorder kept these episodes because MetaWorld said success (gripper centre within 5 cm of the goal)
        assert d["max_reward"] == pytest.approx(10.0)
        assert d["min_obj_to_target_m"] <= d["final_obj_to_target_m"] < 0.05
        # the default expert aims the gripper's centre at the goal and goes on after the first success
        assert d["final_obj_to_target_m"] < 0.04


def test_panda_spatial_runs_are_evaluated_on_their_recorded_placements_with_the_panda_env(tmp_path, monkeypatch):
    # no training and no MuJoCo: a fake recording and checkpoint; the evaluation command is captured and answered
    import subprocess

    from benchmarks import eval_train_placements as etp

    placements = [[0.44, 0.0, 0.0], [0.55, 0.14, -0.78]]
    data = tmp_path / "data" / "panda_lift-cube_fps-centre_s0_n2"
    (data / "meta").mkdir(parents=True)
    attempts = [{"success": True, "episode_index": 1, "placement": placements[1]},
                {"success": False, "episode_index": None, "placement": [0.3, 0.1, 0.2]},
                {"success": True, "episode_index": 0, "placement": placements[0]}]  # fmt: skip
    (data / "meta" / "rnd_recording.json").write_text(json.dumps({"settings": {"suite": "panda"}, "attempts": attempts}))
    run = tmp_path / "work" / "runs" / "spatial" / "rnd_ai" / "lift-cube" / "n2" / "seed0"
    (run / "train" / "checkpoints" / "last" / "pretrained_model").mkdir(parents=True)
    seen = []

    def fake_run(argv, check, cwd):
        seen.append(argv)
        flags = dict(x.partition("=")[::2] for x in argv if x.startswith("--"))
        assert json.loads(Path(flags["--placements"]).read_text()) == placements  # episode order, failures left out
        out = tmp_path / flags["--output-dir"]
        out.mkdir(parents=True, exist_ok=True)
        (out / "eval_info.json").write_text(json.dumps({"per_task": [{"metrics": {
            "successes": [True, False], "max_rewards": [1.0, 0.0]}}]}))  # fmt: skip

    monkeypatch.setattr(subprocess, "run", fake_run)
    out = tmp_path / "tp.json"
    assert etp.main(["--suite", "panda", "--protocol", "spatial", "--tasks", "lift-cube", "--demos", "2",
                     "--methods", "rnd_ai,act", "--work", str(tmp_path / "work"), "--data", str(tmp_path / "data"),
                     "--out", str(out)]) == 0  # fmt: skip
    assert len(seen) == 1  # ACT has no checkpoint here: skipped
    assert "--env-type=rnd_panda" in seen[0] and "--episode-length=120" in seen[0] and "--task=lift-cube" in seen[0]
    row = json.loads(out.read_text())["rows"][0]
    assert (row["method"], row["successes"], row["episodes"], row["placements"]) == ("rnd_ai", 1, 2, placements)
