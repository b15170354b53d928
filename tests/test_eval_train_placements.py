"""benchmarks/eval_train_placements.py's demo replay: the recorded actions, replayed from each demo's placement,
must bring the gripper where the recording did (reference: the recorder's own success flags and frame counts,
and MetaWorld's own `obj_to_target`)."""

import json

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
