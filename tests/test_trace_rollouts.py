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
