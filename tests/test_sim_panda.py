"""Panda + Robotiq suite (gym-hil's assets): env, experts, calibration against MuJoCo's own rendering, the
``ee_delta`` action adapter against the simulator, the LeRobot env config and the recorder.

Independent references: MuJoCo's segmentation rendering (marker spheres / the gripper geoms) versus our
calibration's projection / our renderer's mask of the extracted mesh; the controller's target pose and
the EE poses actually reached versus the adapter's prediction from the recorded actions.
"""

import json
import math

import numpy as np
import pytest
import torch

pytest.importorskip("gym_hil", reason="gym-hil is not installed (pip install --no-deps gym-hil==0.1.14)")
pytest.importorskip("mujoco")

from tests.helpers import gl_available, gripper_mask_iou, marker_errors, subtree_geoms  # noqa: E402

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

from lerobot_rnd.sim.panda_env import PANDA_TASKS, RnDPandaEnv  # noqa: E402
from lerobot_rnd.sim.panda_experts import PandaExpert  # noqa: E402
from lerobot_rnd.sim.panda_scene import FINGER_BODIES, GRIPPER_ROOT_BODY, HOME_QUAT, START_POS  # noqa: E402


def small_env(task, **kw):
    kw.setdefault("camera_names", ("front",))
    kw.setdefault("observation_height", 32)
    kw.setdefault("observation_width", 32)
    return RnDPandaEnv(task, **kw)


def yaw_of_ee(T):
    x = T[:3, 0]  # EE x axis (horizontal when pointing down); home: world +x
    return math.atan2(x[1], x[0])


# --------------------------------------------------------------------------------------------------
# env basics
# --------------------------------------------------------------------------------------------------
def test_observation_layout_and_action_semantics():
    env = RnDPandaEnv("lift-cube", observation_height=64, observation_width=96)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and info["is_success"] is False
    assert set(obs["pixels"]) == {"front", "wrist"}
    assert obs["pixels"]["wrist"].shape == (64, 96, 3) and obs["pixels"]["wrist"].dtype == np.uint8
    s = obs["agent_pos"]
    assert s.shape == (8,) and s.dtype == np.float32
    np.testing.assert_allclose(s[:3], env.data.site("pinch").xpos, atol=1e-6)
    np.testing.assert_allclose(s[:3], START_POS, atol=2e-3)
    np.testing.assert_allclose(s[3:7], HOME_QUAT, atol=5e-3)  # pointing down, canonical sign
    assert s[7] > 0.95  # open
    # one step: the target moves by 0.02 m / 0.1 rad per unit in the WORLD frame; gripper is absolute
    T0 = env.mocap_pose()
    a = np.array([1.0, -0.5, 0.25, 0.0, 0.0, 1.0, 1.0], np.float32)
    obs, r, term, trunc, info = env.step(a)
    T1 = env.mocap_pose()
    np.testing.assert_allclose(T1[:3, 3] - T0[:3, 3], [0.02, -0.01, 0.005], atol=1e-9)
    Rz = np.array([[math.cos(0.1), -math.sin(0.1), 0], [math.sin(0.1), math.cos(0.1), 0], [0, 0, 1]])
    np.testing.assert_allclose(T1[:3, :3], Rz @ T0[:3, :3], atol=1e-9)
    assert env.data.ctrl[env._grip_act] == pytest.approx(255.0)
    env.step(np.array([0, 0, 0, 0, 0, 0, 5.0], np.float32))  # clipped to [-1, 1]
    assert env.data.ctrl[env._grip_act] == pytest.approx(255.0)
    for _ in range(6):
        obs, *_ = env.step(np.array([0, 0, 0, 0, 0, 0, 1.0], np.float32))
    assert obs["agent_pos"][7] < 0.1  # closed on nothing
    q = obs["agent_pos"][3:7]
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-5) and q @ HOME_QUAT >= 0
    assert env.render().shape == (64, 192, 3)
    with pytest.raises(ValueError, match="7"):
        env.step(np.zeros(4, np.float32))
    env.close()


def test_reset_with_fixed_placement_is_reproducible():
    env = small_env("push-block", camera_names=("front", "wrist"))
    placement = np.array([0.45, -0.05, 0.3, 0.40, 0.10])
    a = np.array([0.3, -0.2, -0.4, 0.1, 0.0, -0.3, 1.0], np.float32)
    obs1, _ = env.reset(options={"placement": placement})
    for _ in range(4):
        obs1, *_ = env.step(a)
    np.testing.assert_allclose(env.placement, placement)
    env.reset(seed=123)  # something else in between (moves the target disc)
    obs2, _ = env.reset(options={"placement": placement})
    for _ in range(4):
        obs2, *_ = env.step(a)
    np.testing.assert_array_equal(obs1["agent_pos"], obs2["agent_pos"])
    for c in env.camera_names:
        np.testing.assert_array_equal(obs1["pixels"][c], obs2["pixels"][c])
    # the objects sit where the placement puts them
    np.testing.assert_allclose(env.object_pos()[:2], placement[:2], atol=2e-3)
    q = env.object_quat()
    assert 2 * math.atan2(q[3], q[0]) == pytest.approx(placement[2], abs=0.02)
    np.testing.assert_allclose(env.target_pos()[:2], placement[3:5], atol=1e-9)
    # seeded random placements are reproducible and differ between seeds
    env.reset(seed=7)
    p7 = env.placement
    env.reset(seed=8)
    assert not np.allclose(env.placement, p7)
    env.reset(seed=7)
    np.testing.assert_array_equal(env.placement, p7)
    assert env.is_valid_placement(p7)
    # target on top of the block / wrong size: refused
    bad = np.array([0.45, 0.0, 0.0, 0.45, 0.01])
    assert not env.is_valid_placement(bad)
    with pytest.raises(ValueError, match="invalid placement"):
        env.reset(options={"placement": bad})
    with pytest.raises(ValueError, match="5 numbers"):
        env.reset(options={"placement": [0.4, 0.0, 0.0]})
    env.close()


# --------------------------------------------------------------------------------------------------
# experts
# --------------------------------------------------------------------------------------------------
EXPERT_PLACEMENTS = {
    "lift-cube": [[0.36, 0.12, 0.7], [0.52, -0.10, -0.6]],  # yaw near +-45 degrees
    "push-block": [[0.40, -0.08, 0.5, 0.55, 0.05], [0.50, 0.10, -0.3, 0.35, -0.02]],
    "press-button": [[0.35, -0.12, 0.3], [0.53, 0.13, -0.7]],
    "pick-place": [[0.38, 0.10, 0.7, 0.52, -0.12]],
    "slide-block": [[0.38, -0.14, -0.78], [0.50, 0.08, 0.78]],  # opposite corners, yaw near -+45 degrees
    "lift-red-cube": [[0.36, 0.12, 0.7, 0.50, -0.02, -0.3]],  # the other cube 19 cm away
    "lift-blue-cube": [[0.52, -0.10, -0.6, 0.45, 0.03, 0.2]],  # 15 cm
}


@pytest.mark.parametrize("task", PANDA_TASKS)
def test_expert_succeeds(task):
    env = small_env(task, episode_length=120)
    expert = PandaExpert(task)
    for placement in EXPERT_PLACEMENTS[task]:
        env.reset(options={"placement": placement})
        grasp_yaw = None
        for _ in range(120):
            a = expert.act(env)
            assert a.shape == (7,) and a.dtype == np.float32 and np.abs(a).max() <= 1.0
            _, _, term, trunc, info = env.step(a)
            if task in ("lift-cube", "pick-place", "lift-red-cube", "lift-blue-cube") and grasp_yaw is None and a[6] > 0:
                grasp_yaw = yaw_of_ee(env.ee_pose())
            if term or trunc:
                break
        assert term and info["is_success"] and not trunc, (task, placement)
        if grasp_yaw is not None:  # the gripper turned to the cube's yaw (6-DoF), modulo 90 degrees
            d = (grasp_yaw - placement[2] + math.pi / 4) % (math.pi / 2) - math.pi / 4
            assert abs(d) < math.radians(4), (math.degrees(grasp_yaw), placement)
            assert abs(grasp_yaw) > math.radians(30)
    env.close()


def test_two_cube_tasks_show_the_same_scene_and_only_the_task_decides_success():
    """lift-red-cube and lift-blue-cube (issue 35's pair): with the cubes at the same poses the two tasks render
    identical images and states, yet the same actions (the red expert's) succeed in one and not the other; the
    placement lists the task's cube first, so one seed draws the same pose for the cube each task lifts."""
    red, blue = small_env("lift-red-cube", episode_length=60), small_env("lift-blue-cube", episode_length=60)
    pose_red, pose_blue = [0.38, 0.10, 0.6], [0.50, -0.06, -0.2]
    obs_r, _ = red.reset(options={"placement": pose_red + pose_blue})
    obs_b, _ = blue.reset(options={"placement": pose_blue + pose_red})
    np.testing.assert_array_equal(obs_r["pixels"]["front"], obs_b["pixels"]["front"])
    np.testing.assert_array_equal(obs_r["agent_pos"], obs_b["agent_pos"])
    assert red.task_description != blue.task_description and "red" in red.task_description
    np.testing.assert_allclose(red.object_pos()[:2], pose_red[:2], atol=1e-3)
    np.testing.assert_allclose(blue.object_pos()[:2], pose_blue[:2], atol=1e-3)
    expert = PandaExpert("lift-red-cube")
    for _ in range(60):
        a = expert.act(red)
        _, _, term_r, _, info_r = red.step(a)
        _, _, term_b, _, info_b = blue.step(a)
        assert not info_b["is_success"]
        if term_r:
            break
    assert info_r["is_success"] and not term_b
    # the red cube went up in both envs, the blue one stayed on the table
    assert red.data.body("red_cube").xpos[2] > 0.09 and blue.data.body("red_cube").xpos[2] > 0.09
    assert abs(blue.data.body("blue_cube").xpos[2] - 0.02) < 2e-3
    # one seed, the same pose for the cube to lift; the other cube's yaw is periodic too
    red.reset(seed=5)
    blue.reset(seed=5)
    np.testing.assert_array_equal(red.placement, blue.placement)
    np.testing.assert_allclose(red.placement_periods(), [0, 0, math.pi / 2, 0, 0, math.pi / 2])
    too_close = [0.40, 0.0, 0.0, 0.48, 0.05, 0.0]  # 9.4 cm apart
    with pytest.raises(ValueError, match="cube-cube distance >= 0.12"):
        red.reset(options={"placement": too_close})
    red.close()
    blue.close()


def test_slide_block_target_turns_with_the_block_and_so_does_the_push():
    """slide-block (RLBench's slide-block-to-target): the target disc lies 10 cm along the block's own +y axis, read
    from MuJoCo's pose of the block body, whatever the yaw; yaws 90 degrees apart are different scenes (no period);
    the expert pushes along that axis with the gripper turned by the block's yaw (modulo 180 degrees)."""
    env = small_env("slide-block", episode_length=80)
    assert env.placement_periods()[2] == 0.0
    push = small_env("push-block")
    assert push.placement_periods()[2] == pytest.approx(math.pi / 2)
    push.close()
    low, high = env.placement_space.low, env.placement_space.high
    rng = np.random.default_rng(0)
    for placement in [low, high, [low[0], high[1], high[2]], *rng.uniform(low, high, (3, 3))]:
        env.reset(options={"placement": placement})
        y_axis = env.data.body("block").xmat.reshape(3, 3)[:, 1]
        np.testing.assert_allclose(env.target_pos()[:2] - env.object_pos()[:2], 0.10 * y_axis[:2], atol=2e-3)
    q_a, q_b = [0.44, -0.03, -0.7], [0.44, -0.03, -0.7 + math.pi / 2]  # the block looks the same, the target does not
    env.reset(options={"placement": q_a})
    t_a = env.target_pos()
    with pytest.raises(ValueError, match="invalid placement"):
        env.reset(options={"placement": q_b})  # outside the +-45-degree range, not folded into it
    assert t_a[0] > 0.44 + 0.05  # yaw -0.7 rad: the block's +y points to +x as much as to +y
    expert = PandaExpert("slide-block")
    for yaw in (-0.7, 0.7):
        env.reset(options={"placement": [0.44, -0.03, yaw]})
        pushing = []
        for _ in range(80):
            _, _, term, _, info = env.step(expert.act(env))
            if expert.phase == 2:
                pushing.append(yaw_of_ee(env.ee_pose()))
            if term:
                break
        assert info["is_success"] and pushing
        d = (np.median(pushing) - yaw + math.pi / 2) % math.pi - math.pi / 2
        assert abs(d) < math.radians(5), (math.degrees(np.median(pushing)), math.degrees(yaw))
    env.close()


# --------------------------------------------------------------------------------------------------
# calibration vs MuJoCo's rendering
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def env_tilted():
    """lift-cube with the EE moved, turned and tilted (so the wrist camera's rigid mount is tested)."""
    env = RnDPandaEnv("lift-cube", terminate_on_success=False)
    env.reset(options={"placement": [0.45, 0.05, 0.3]})
    for _ in range(4):
        env.step(np.array([-0.5, 0.5, -0.5, 0.6, -0.5, 1.0, -1.0], np.float32))
    for _ in range(6):
        env.step(np.array([0, 0, 0, 0, 0, 0, -1.0], np.float32))
    yield env
    env.close()


def test_ee_is_tilted(env_tilted):
    R = env_tilted.ee_pose()[:3, :3]
    z = R[:, 2]
    assert math.degrees(math.acos(-z[2])) > 10  # the fingers no longer point straight down
    assert env_tilted.gripper_opening() > 0.95


@pytest.mark.parametrize("camera", ["front", "wrist"])
def test_calibration_matches_mujoco_projection(env_tilted, camera):
    env = env_tilted
    emb = env.embodiment(max_faces=1500)
    cam = emb.cameras[f"observation.images.{camera}"]
    assert cam.is_static == (camera == "front")
    markers = dict(depth_range=(0.15, 1.2), extra_points=env.ee_pose()[:3, 3])  # closer, plus the EE site
    errs = marker_errors(env, cam, cam.image_size, **markers)
    assert len(errs) >= 14
    assert np.abs(errs.mean(0)).max() < 0.05, errs.mean(0)
    assert np.abs(errs).max() < 0.35, np.abs(errs).max()
    big = cam.resized(384, 384)
    errs = marker_errors(env, big, (384, 384), seed=1, **markers)
    assert len(errs) >= 14
    assert np.abs(errs.mean(0)).max() < 0.05 and np.abs(errs).max() < 0.35, errs


def test_gripper_mask_iou_and_preset(env_tilted):
    """Our renderer's mask of the extracted, simplified mesh at the pose read from observation.state vs
    MuJoCo's segmentation of the same gripper geoms (drawn alone); the preset matches the env's."""
    from lerobot_rnd.embodiment import load_embodiment

    env = env_tilted
    emb = env.embodiment()
    state = torch.as_tensor(env.state(), dtype=torch.float64)
    T_we = emb.ee_pose_source.ee_pose(state)
    np.testing.assert_allclose(T_we.numpy(), env.ee_pose(), atol=1e-6)
    assert emb.ee_pose_source.gripper(state).item() < 0.05  # open
    cases = (("front", (GRIPPER_ROOT_BODY,), "full"), ("wrist", FINGER_BODIES, "fingers"))
    for cam_name, roots, mesh in cases:
        key = f"observation.images.{cam_name}"
        assert emb.camera_mesh[key] == mesh
        iou, n = gripper_mask_iou(env, emb, key, subtree_geoms(env.model, roots))
        assert n > 150 and iou >= 0.9, (cam_name, iou, n)
    preset = load_embodiment("panda_robotiq")
    assert preset.name == "panda_robotiq" and preset.action_adapter == emb.action_adapter
    assert preset.ee_pose_source.to_dict() == emb.ee_pose_source.to_dict()
    for key, cam in emb.cameras.items():
        np.testing.assert_allclose(preset.cameras[key].K, cam.K)
        T = cam.T_world_cam if cam.is_static else cam.T_ee_cam
        Tp = preset.cameras[key].T_world_cam if cam.is_static else preset.cameras[key].T_ee_cam
        np.testing.assert_allclose(Tp, T, atol=1e-9)


# --------------------------------------------------------------------------------------------------
# action adapter vs the simulator
# --------------------------------------------------------------------------------------------------
def test_ee_delta_adapter_predicts_reached_poses():
    """``adapter.to_rnd(actions[t:t+K], T_world_ee(t))`` vs the EE poses reached at t+1..t+K on expert
    rollouts: exact for the controller's target pose, within the tracking lag for the real EE; the other
    frame convention ("ee") would be far off."""
    from lerobot_rnd.action_adapters import ActionAdapter
    from lerobot_rnd.geometry import invert_transform, so3_log

    K = 4
    env = small_env("lift-cube", terminate_on_success=False)
    spec = env.embodiment(max_faces=1500).action_adapter
    assert spec["type"] == "ee_delta" and spec["frame"] == "world"
    adapter = ActionAdapter.from_dict(spec)
    wrong = ActionAdapter.from_dict({**spec, "frame": "ee"})
    src = env.embodiment(max_faces=1500).ee_pose_source
    expert = PandaExpert("lift-cube")
    perr, rerr, target_err, wrong_err = [], [], [], []
    for placement in ([0.40, 0.08, 0.6], [0.50, -0.10, -0.4]):
        obs, _ = env.reset(options={"placement": placement})
        states, actions, targets = [obs["agent_pos"]], [], [env.mocap_pose()]
        for _ in range(40):
            a = expert.act(env)
            obs, *_ = env.step(a)
            actions.append(a)
            states.append(obs["agent_pos"])
            targets.append(env.mocap_pose())
        T = src.ee_pose(torch.as_tensor(np.array(states), dtype=torch.float64))
        Tm = torch.as_tensor(np.array(targets))
        A = torch.as_tensor(np.array(actions), dtype=torch.float64)
        for t in range(len(actions) - K):
            pred, g = adapter.to_rnd(A[t : t + K], T[t])
            assert torch.equal(g, torch.where(A[t : t + K, 6] > 0, 1.0, -1.0).to(g))
            actual = invert_transform(T[t])[None] @ T[t + 1 : t + 1 + K]
            perr.append((pred[:, :3, 3] - actual[:, :3, 3]).norm(dim=-1).numpy())
            rerr.append(so3_log(pred[:, :3, :3].transpose(-1, -2) @ actual[:, :3, :3]).norm(dim=-1).numpy())
            wpred, _ = wrong.to_rnd(A[t : t + K], T[t])
            wrong_err.append((wpred[:, :3, 3] - actual[:, :3, 3]).norm(dim=-1).numpy())
            predm, _ = adapter.to_rnd(A[t : t + K], Tm[t])
            actm = invert_transform(Tm[t])[None] @ Tm[t + 1 : t + 1 + K]
            target_err.append((predm - actm).abs().max().item())
            # and back: from_rnd reproduces the (clipped) actions
            back = adapter.from_rnd(pred, g, T[t])
            np.testing.assert_allclose(back[:, :6].numpy(), A[t : t + K, :6].numpy(), atol=1e-6)
    perr, rerr, wrong_err = np.array(perr), np.degrees(np.array(rerr)), np.array(wrong_err)
    assert max(target_err) < 1e-9  # the action definition IS the adapter's (world frame, scales)
    assert perr.mean() < 0.010 and np.percentile(perr, 95) < 0.022 and perr.max() < 0.035, (
        perr.mean(0), perr.max())  # fmt: skip
    assert rerr.mean() < 2.5 and rerr.max() < 10.0, (rerr.mean(), rerr.max())
    assert wrong_err.mean() > 4 * perr.mean()
    env.close()


# --------------------------------------------------------------------------------------------------
# LeRobot integration, recorder, gym-hil compatibility
# --------------------------------------------------------------------------------------------------
def test_recorder_writes_loadable_dataset(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_rnd.embodiment import Embodiment
    from lerobot_rnd.sim.record import main

    root = tmp_path / "panda_press"
    assert main(["--suite", "panda", "--task", "press-button", "--episodes", "2", "--root", str(root),
                 "--repo-id", "local/panda_press", "--image-size", "64", "--extra-steps", "2",
                 "--max-steps", "40"]) == 0  # fmt: skip
    ds = LeRobotDataset("local/panda_press", root=root)
    assert ds.num_episodes == 2 and ds.fps == 10 and ds.meta.robot_type == "panda"
    item = ds[0]
    assert item["observation.images.front"].shape == (3, 64, 64)
    assert item["observation.images.wrist"].shape == (3, 64, 64)
    assert item["observation.state"].shape == (8,) and item["action"].shape == (7,)
    assert item["task"] == "Press the red button"
    emb = Embodiment.load_json(root / "meta" / "rnd_embodiment.json")
    emb.validate_against(ds.meta.features)
    assert emb.name == "panda_robotiq" and emb.action_adapter["frame"] == "world"
    rec = json.loads((root / "meta" / "rnd_recording.json").read_text())
    assert rec["settings"]["suite"] == "panda" and rec["settings"]["cameras"] == ["front", "wrist"]
    assert sum(a["success"] for a in rec["attempts"]) == 2
    # every episode ends pressed (success) plus the extra frames
    n0 = ds.meta.episodes["dataset_to_index"][0]
    assert rec["attempts"][0]["num_frames"] == n0 == rec["attempts"][0]["steps_to_success"] + 2


def test_clear_error_without_gym_hil(monkeypatch):
    """The module imports (and registers the env ids / ``rnd_panda``) without gym-hil; building a scene
    then fails with the install command."""
    import importlib.util

    from lerobot_rnd.sim import panda_scene

    real = importlib.util.find_spec
    monkeypatch.setattr(
        panda_scene.importlib.util, "find_spec", lambda name, *a: None if name == "gym_hil" else real(name, *a)
    )
    with pytest.raises(ImportError, match="pip install --no-deps gym-hil==0.1.14"):
        panda_scene.gym_hil_assets_dir()
