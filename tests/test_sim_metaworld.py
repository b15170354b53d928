"""MetaWorld env, calibration against MuJoCo's own rendering, LeRobot env config and the recorder.

Independent references: MuJoCo's segmentation rendering (where it draws a marker sphere / the gripper
geoms) versus our calibration's projection / our renderer's mask of the extracted mesh.
"""

import json

import numpy as np
import pytest

pytest.importorskip("metaworld")
pytest.importorskip("mujoco")

from tests.helpers import gl_available, gripper_mask_iou, marker_errors, subtree_geoms  # noqa: E402

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

from lerobot_rnd.camera_calibration import camera_from_mujoco  # noqa: E402
from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv  # noqa: E402
from lerobot_rnd.sim.metaworld_experts import MetaWorldExpert  # noqa: E402


@pytest.fixture(scope="module")
def env_mid_motion():
    """reach-v3 after 25 expert steps: the hand moves and is tilted by a few degrees."""
    env = RnDMetaWorldEnv("reach-v3", flip_cameras=("corner2",))
    ex = MetaWorldExpert("reach-v3")
    env.reset(seed=0)
    for _ in range(25):
        env.step(ex(env.raw_observation))
    yield env
    env.close()


def test_hand_is_tilted(env_mid_motion):
    R = env_mid_motion.ee_pose()[:3, :3]
    R0 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # mocap orientation
    angle = np.degrees(np.arccos(np.clip((np.trace(R0.T @ R) - 1) / 2, -1, 1)))
    assert angle > 1.0  # the EE-mounted camera check below is meaningful only if the hand is not at R0


@pytest.mark.parametrize("camera", ["corner2", "behindGripper"])
def test_calibration_matches_mujoco_projection(env_mid_motion, camera):
    env = env_mid_motion
    emb = env.embodiment()
    cam = emb.cameras[f"observation.images.{camera}"]
    errs = marker_errors(env, cam, cam.image_size)
    assert len(errs) >= 14
    assert np.abs(errs.mean(0)).max() < 0.05, errs.mean(0)  # a 0.5 px principal point error would show
    assert np.abs(errs).max() < 0.35, np.abs(errs).max()
    # resized intrinsics vs MuJoCo rendering at 3x the size
    big = cam.resized(384, 384)
    errs = marker_errors(env, big, (384, 384), seed=1)
    assert len(errs) >= 14
    assert np.abs(errs.mean(0)).max() < 0.05 and np.abs(errs).max() < 0.35, errs


def test_non_square_intrinsics(env_mid_motion):
    env = env_mid_motion
    cam = camera_from_mujoco(env.model, env.data, "corner3", (96, 160))
    assert cam.K[0, 0] == pytest.approx(cam.K[1, 1])
    errs = marker_errors(env, cam, (96, 160), seed=2)
    assert len(errs) >= 14 and np.abs(errs.mean(0)).max() < 0.05 and np.abs(errs).max() < 0.35, errs


def gripper_iou(env, key, size=None):
    geoms = subtree_geoms(env.model, ["right_hand"], max_group=None)
    return gripper_mask_iou(env, env.embodiment(), key, geoms, size)


def test_gripper_mask_iou(env_mid_motion):
    """Our renderer's mask of the extracted, simplified mesh at the pose read from observation.state vs
    MuJoCo's segmentation of the gripper geoms (drawn alone: the arm would occlude part of them)."""
    iou, n = gripper_iou(env_mid_motion, "observation.images.behindGripper")
    assert n > 300 and iou >= 0.92, (iou, n)
    iou, n = gripper_iou(env_mid_motion, "observation.images.corner2")  # about 110 px: boundary-limited
    assert n > 80 and iou >= 0.85, (iou, n)
    for key in ("observation.images.corner2", "observation.images.behindGripper"):
        iou, n = gripper_iou(env_mid_motion, key, size=(384, 384))
        assert n > 900 and iou >= 0.93, (key, iou, n)


def test_reset_with_fixed_placement_is_reproducible():
    env = RnDMetaWorldEnv("push-v3", episode_length=50)
    placement = np.array([0.05, 0.62, 0.02, -0.05, 0.85, 0.01])
    obs1, _ = env.reset(options={"placement": placement})
    a = np.array([0.3, -0.2, 0.1, 1.0], np.float32)
    for _ in range(5):
        obs1, *_ = env.step(a)
    np.testing.assert_allclose(env.placement, placement)
    obs2, _ = env.reset(seed=123)  # something else in between
    obs2, _ = env.reset(options={"placement": placement})
    for _ in range(5):
        obs2, *_ = env.step(a)
    np.testing.assert_array_equal(obs1["agent_pos"], obs2["agent_pos"])
    for c in env.camera_names:
        np.testing.assert_array_equal(obs1["pixels"][c], obs2["pixels"][c])
    # the object sits where the placement puts it
    np.testing.assert_allclose(env.data.body("obj").xpos[:2], placement[:2], atol=0.01)
    # seeded random placements are reproducible and differ between seeds
    env.reset(seed=7)
    p7 = env.placement
    env.reset(seed=8)
    assert not np.allclose(env.placement, p7)
    env.reset(seed=7)
    np.testing.assert_array_equal(env.placement, p7)
    # MetaWorld would loop forever on object == goal: refused with a clear error
    bad = np.array([0.0, 0.7, 0.02, 0.0, 0.7, 0.02])
    assert not env.is_valid_placement(bad)
    with pytest.raises(ValueError, match="rejects placement"):
        env.reset(options={"placement": bad})
    env.close()


def test_observation_layout_and_expert_success():
    env = RnDMetaWorldEnv("reach-v3", observation_height=64, observation_width=96, episode_length=200)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert set(obs["pixels"]) == {"corner2", "behindGripper"}
    assert obs["pixels"]["corner2"].shape == (64, 96, 3) and obs["pixels"]["corner2"].dtype == np.uint8
    s = obs["agent_pos"]
    assert s.shape == (8,) and s.dtype == np.float32
    np.testing.assert_allclose(s[:3], env.raw_observation[:3], atol=1e-6)  # MetaWorld's hand position
    np.testing.assert_allclose(s[3], env.raw_observation[3], atol=1e-6)  # MetaWorld's gripper opening
    assert np.linalg.norm(s[4:]) == pytest.approx(1.0, abs=1e-5)
    ex = MetaWorldExpert("reach-v3")
    for t in range(200):
        obs, _, term, trunc, info = env.step(ex(env.raw_observation))
        if term or trunc:
            break
    assert term and info["is_success"] and not trunc
    assert env.render().shape == (64, 192, 3)
    env.close()


@pytest.mark.parametrize("reach_target", ["tcp", "hand"])
def test_reach_expert_puts_the_gripper_centre_on_the_goal(reach_target):
    """MetaWorld's reach policy parks the hand on the goal, so the gripper's centre (where MetaWorld measures
    success, radius 5 cm) stops about 4.5 cm away; reach_target="tcp" puts the centre on the goal. Reference:
    MetaWorld's own `obj_to_target` (and its `tcp_center` against the goal it placed)."""
    env = RnDMetaWorldEnv("reach-v3", observation_height=32, observation_width=32, episode_length=150,
                          terminate_on_success=False)  # fmt: skip
    ex = MetaWorldExpert("reach-v3", reach_target=reach_target)
    env.reset(seed=5)
    for _ in range(150):
        env.step(ex.act(env))
    dist = env.metaworld_info["obj_to_target"]
    np.testing.assert_allclose(dist, np.linalg.norm(env.tcp_center - env.raw_observation[-3:]), atol=1e-6)
    if reach_target == "tcp":
        assert dist < 0.01, dist
    else:
        assert 0.03 < dist < 0.05, dist
    env.close()


def test_state_layout_with_mocap():
    env = RnDMetaWorldEnv("reach-v3", state_layout="pos_grip_quat_mocap", camera_names=("corner2",))
    obs, _ = env.reset(seed=0)
    assert obs["agent_pos"].shape == (11,)
    np.testing.assert_allclose(obs["agent_pos"][8:], env.mocap_pos(), atol=1e-6)
    env.close()


def test_weld_patch_fixes_lerobot_metaworld():
    import metaworld

    from lerobot_rnd.sim.metaworld_env import patch_metaworld_for_mujoco

    patch_metaworld_for_mujoco()  # what the rnd_mw env does before it builds MetaWorld (idempotent)
    mt1 = metaworld.MT1("reach-v3", seed=0)  # fails on MuJoCo >= 3.4 without the patch
    env = mt1.train_classes["reach-v3"]()
    env.set_task(mt1.train_tasks[0])
    obs, _ = env.reset()
    assert obs.shape == (39,)
    env.close()


def test_recorder_writes_loadable_dataset(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_rnd.embodiment import Embodiment
    from lerobot_rnd.sim.record import RecordSettings, main, record_metaworld

    root = tmp_path / "mw_reach"
    settings = RecordSettings(
        task="reach-v3", episodes=2, root=str(root), repo_id="local/mw_reach", placements="fps", fps_pool=64,
        image_size=64, extra_steps=3,
    )  # fmt: skip
    summary = record_metaworld(settings, progress=False)
    assert summary["episodes"] == 2 and summary["failures"] == 0
    # 64-px demos must be evaluated with 64-px images, and the summary says how
    assert summary["eval_env_args"] == ["--env.observation_height=64", "--env.observation_width=64"]
    assert "--env.observation_height=64" in summary["message"]
    # resume to 3 episodes through the CLI
    assert main(["--task", "reach-v3", "--episodes", "3", "--root", str(root), "--repo-id", "local/mw_reach",
                 "--placements", "fps", "--fps-pool", "64", "--image-size", "64", "--extra-steps", "3",
                 "--resume"]) == 0  # fmt: skip
    with pytest.raises(FileExistsError, match="--resume"):
        record_metaworld(settings, progress=False)

    ds = LeRobotDataset("local/mw_reach", root=root)
    assert ds.num_episodes == 3 and ds.fps == 80
    item = ds[0]
    assert item["observation.images.corner2"].shape == (3, 64, 64)
    assert item["observation.images.behindGripper"].shape == (3, 64, 64)
    assert item["observation.state"].shape == (8,) and item["action"].shape == (4,)
    assert item["task"] == "Reach a goal position"
    emb = Embodiment.load_json(root / "meta" / "rnd_embodiment.json")
    emb.validate_against(ds.meta.features)
    rec = json.loads((root / "meta" / "rnd_recording.json").read_text())
    idx = [a["placement_index"] for a in rec["attempts"]]
    assert idx == list(range(len(idx))) and sum(a["success"] for a in rec["attempts"]) == 3
    # every episode is a success followed by the extra frames
    last = ds[ds.meta.episodes["dataset_to_index"][0] - 1]
    st = last["observation.state"].numpy()
    goal = np.asarray(rec["attempts"][0]["placement"][3:])
    # success: the gripper's centre (tcp, 4.5 cm straight below the hand body of the state) within 5 cm of the goal
    assert np.linalg.norm(st[:3] - (goal + [0.0, 0.0, 0.045])) < 0.06


def test_the_evaluation_env_shows_what_the_demos_show(tmp_path):
    """The frames lerobot-eval's env renders for a demo's placement and actions, built from the recording's
    ``recorded_env_args``, are the demo's frames pixel for pixel, also for non-default cameras (MetaWorld's own
    corner2 pose, 64-px images). Built with the env's defaults instead, corner2 shows another view."""
    import io

    import gymnasium as gym
    import pyarrow.parquet as pq
    from PIL import Image

    import lerobot_policy_rnd  # noqa: F401  (registers the gym ids)
    from benchmarks.harness.grid_eval import env_config
    from lerobot_rnd.sim.record import RecordSettings, record_metaworld, recorded_env_args

    root = tmp_path / "mw_reach"
    s = RecordSettings(task="reach-v3", episodes=1, root=str(root), repo_id="local/mw_reach", image_size=64,
                       extra_steps=0, lerobot_corner2_pos=False)  # fmt: skip
    record_metaworld(s, progress=False)
    rec = json.loads((root / "meta" / "rnd_recording.json").read_text())
    placement = next(a["placement"] for a in rec["attempts"] if a["success"])
    table = pq.read_table(sorted((root / "data").glob("*/*.parquet")))
    actions = np.asarray(table.column("action").to_pylist(), dtype=np.float32)

    def frame(cam, i):
        return np.asarray(Image.open(io.BytesIO(table.column(f"observation.images.{cam}")[i].as_py()["bytes"])))

    def corner2_error(env_args) -> float:
        cfg = env_config("reach-v3", 300, env_args)
        env = gym.make(cfg.gym_id, disable_env_checker=True,
                       **{**cfg.gym_kwargs, "placement": "fixed", "placements": [placement]})  # fmt: skip
        try:
            obs, _ = env.reset(seed=0)
            err = 0.0
            for i in range(6):
                assert obs["pixels"]["corner2"].shape == frame("corner2", i).shape
                np.testing.assert_array_equal(obs["pixels"]["behindGripper"], frame("behindGripper", i))
                err = max(err, float(np.abs(obs["pixels"]["corner2"].astype(float) - frame("corner2", i)).mean()))
                obs, *_ = env.step(actions[i])
            return err
        finally:
            env.close()

    assert corner2_error(recorded_env_args(rec["settings"])) == 0.0
    assert corner2_error(["--env.observation_height=64", "--env.observation_width=64"]) > 10.0
