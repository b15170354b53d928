"""benchmarks/run_benchmark.py --suite panda (fast): the commands it would run, furthest point sampling from the
centre of the placement range, the 3-D evaluation grid (x, y, yaw) and its heat maps."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.harness import cli, reports
from benchmarks.harness.grid_eval import grid_axis, grid_placements
from benchmarks.harness.runs import Benchmark
from lerobot_rnd.sim.placements import PlacementSequence, complete_placement, furthest_point_order

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "run_benchmark.py"


def _needs_panda():
    pytest.importorskip("gym_hil", reason="the Panda scenes need gym-hil's assets")


def _dry_run(tmp_path, *extra):
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--out", str(tmp_path / "out"), "--work-dir", str(tmp_path / "work"),
         "--data-dir", str(tmp_path / "data"), "--dry-run", *extra],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    return [line[2:] for line in out.stdout.splitlines() if line.startswith("$ ")]


# ---------------------------------------------------------------------------------------------- commands
def test_panda_spatial_dry_run_records_fps_from_the_centre_trains_panda_configs_and_evaluates_rnd_panda(tmp_path):
    _needs_panda()
    cmds = _dry_run(tmp_path, "--suite", "panda", "--scale", "cpu", "--protocol", "spatial", "--tasks", "push-block",
                    "--demos", "2,4", "--methods", "rnd_ai,act,diffusion")  # fmt: skip
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 2
    for c in rec:
        assert "--suite panda" in c and "--task push-block" in c and "--placements fps-centre" in c
    assert "panda_push-block_fps-centre_s0_n4" in rec[1] and "--resume" in rec[1]
    assert len([c for c in cmds if "lerobot-train" in c]) == 6  # 3 methods x 2 demo counts
    train = {c.split("--job_name=")[1].split("_push")[0]: c for c in cmds if "lerobot-train" in c}
    assert set(train) == {"rnd_ai", "act", "diffusion"}
    for method, c in train.items():
        assert f"policies_config/panda/{method}_cpu.json" in c and "--env.task=push-block" in c
        assert "--env.episode_length=120" in c and "policies_config/metaworld" not in c
    ev = [c for c in cmds if "_grid_eval" in c]
    assert all("--env-type=rnd_panda" in c and "--task=push-block" in c for c in ev)
    # 3 x 3 positions x 3 yaws = 27 cells, none invalid, in chunks of 10, for 3 methods x 2 demo counts
    assert len(ev) == 18 and sum("ep0020-0026" in c for c in ev) == 6


def test_panda_random_dry_run_evaluates_with_rnd_panda(tmp_path):
    _needs_panda()
    cmds = _dry_run(tmp_path, "--suite", "panda", "--scale", "smoke", "--tasks", "pick-place", "--methods", "act")
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 1 and "--suite panda" in rec[0] and "--placements random" in rec[0]
    (train,) = [c for c in cmds if "lerobot-train" in c]
    assert "policies_config/panda/act_cpu.json" in train and "--policy.dim_model=64" in train  # smoke sizes
    (ev,) = [c for c in cmds if "lerobot-eval" in c]
    assert "--env.type=rnd_panda" in ev and "--env.task=pick-place" in ev and "--seed=1000" in ev
    assert "rnd_mw" not in " ".join(cmds)


def test_panda_multitask_pair_records_one_dataset_and_evaluates_both_tasks(tmp_path):
    """Issue 35's Panda pair (two cubes, the task names the one to lift) through --multitask: one recording of both
    tasks, one training run per method, every evaluation call covering both tasks."""
    _needs_panda()
    cmds = _dry_run(tmp_path, "--suite", "panda", "--scale", "cpu", "--multitask", "--tasks",
                    "lift-red-cube,lift-blue-cube", "--demos", "10", "--methods", "rnd_ai,act")  # fmt: skip
    (rec,) = [c for c in cmds if "lerobot-rnd-record" in c]
    assert "--suite panda" in rec and "--task lift-red-cube,lift-blue-cube" in rec and "--episodes 10" in rec
    train = [c for c in cmds if "lerobot-train" in c]
    assert len(train) == 2 and all("--env.task=lift-red-cube,lift-blue-cube" in c for c in train)
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert ev and all("--env.type=rnd_panda" in c and "--env.task=lift-red-cube,lift-blue-cube" in c for c in ev)


def test_metaworld_spatial_keeps_the_recorders_fps(tmp_path):
    cmds = _dry_run(tmp_path, "--scale", "smoke", "--protocol", "spatial", "--methods", "act")
    (rec,) = [c for c in cmds if "lerobot-rnd-record" in c]
    assert "--placements fps " in rec + " " and "--suite" not in rec and "mw_reach-v3_fps_s0_n3" in rec
    (ev,) = [c for c in cmds if "_grid_eval" in c]
    assert "--env-type" not in ev and "ep0000-0008" in ev  # 3 x 3 grid over the goal's x, y


def test_panda_suite_refuses_metaworld_tasks_and_the_gpu_scale():
    with pytest.raises(SystemExit):
        cli.parse_args(["--suite", "panda", "--scale", "smoke", "--tasks", "reach-v3"])
    with pytest.raises(SystemExit):
        cli.parse_args(["--suite", "panda", "--scale", "gpu"])
    a = cli.parse_args(["--suite", "panda", "--scale", "cpu"])
    assert a.tasks == ["lift-cube", "push-block", "press-button", "pick-place", "slide-block"] and a.episode_length == 120
    assert a.out.endswith("benchmarks/results/panda_cpu") and a.grid == 3 and a.grid_yaws == 3
    assert cli.parse_args(["--scale", "cpu"]).out.endswith("benchmarks/results/cpu")  # MetaWorld unchanged


def test_panda_demos_are_evaluated_with_their_cameras():
    from lerobot_rnd.sim.record import recorded_env_args

    assert recorded_env_args({"suite": "panda", "cameras": ["front", "wrist"], "image_size": 128}) == []
    assert recorded_env_args({"suite": "panda", "cameras": ["front"], "image_size": 96}) == [
        "--env.camera_names=[front]", "--env.observation_height=96", "--env.observation_width=96"]  # fmt: skip


# ---------------------------------------------------------------------------------------------- placements
def test_furthest_point_order_starts_at_the_centre():
    """A hand-made pool in a 2 x 1 range: from the centre (1.0, 0.5) the furthest point is (1.9, 0.9), then
    (0.2, 0.1) (furthest from both), then (0.6, 0.3); the pool-mean start (the default) begins elsewhere."""
    low, high = np.array([0.0, 0.0]), np.array([2.0, 1.0])
    pts = np.array([[0.2, 0.1], [0.4, 0.1], [0.2, 0.2], [0.6, 0.3], [1.0, 0.5], [1.9, 0.9]])
    order = furthest_point_order(pts, 4, low, high, start=(low + high) / 2)
    assert order.tolist() == [4, 5, 0, 3]
    assert furthest_point_order(pts, 1, low, high).tolist() == [3]  # nearest the pool's mean (0.72, 0.35)


def test_furthest_point_order_compares_a_periodic_coordinate_modulo_its_period():
    """Hand-made: from (0, 0, .5), (1, 1, 1) and (1, 1, 0) are both 1.5 away; with coordinate 2 of period 1 they
    are one pose, so after the first the next is (0, 1, .5), not its twin; without the period the twin comes
    first (a tie with (0, 1, .5) at 1.0, broken by the lower index)."""
    low, high = np.zeros(3), np.ones(3)
    pts = np.array([[0, 0, 0.5], [1, 1, 1.0], [1, 1, 0.0], [0, 1, 0.5]])
    assert furthest_point_order(pts, 4, low, high, start=pts[0]).tolist() == [0, 1, 2, 3]
    periodic = furthest_point_order(pts, 4, low, high, start=pts[0], periods=np.array([0, 0, 1.0]))
    assert periodic.tolist() == [0, 1, 3, 2]  # each index once, the twin last


def test_lift_cube_demos_are_not_twins_that_turn_opposite_ways():
    """A cube looks the same at yaw +44 and -44 degrees, but the expert turns the gripper +44 or -44 degrees
    (the nearest equivalent grasp): furthest-point sampling over raw yaw picked such twins at the same corner
    (3 pairs among 8 demos, 1-2 cm apart), which no policy can tell apart. With the yaw compared modulo 90
    degrees (the env's placement_periods), no two of the first 8 demos lie within 3 cm of each other."""
    _needs_panda()
    from lerobot_rnd.sim.panda_env import RnDPandaEnv

    env = RnDPandaEnv("lift-cube")
    try:
        assert env.placement_periods().tolist() == [0.0, 0.0, math.pi / 2]
        seq = PlacementSequence(env, "fps-centre", seed=0, fps_pool=1000)
        xy = np.array([seq[i][:2] for i in range(8)])
    finally:
        env.close()
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(8)
    assert gaps.min() > 0.03


class _FakePushEnv:
    """push-block's placement layout [x, y, yaw, target x, target y]; valid = target 10 cm or more away."""

    task = "push-block"

    class placement_space:  # noqa: N801 - mimics a gymnasium Box
        low = np.array([0.36, -0.12, -math.pi / 4, 0.32, -0.2])
        high = np.array([0.54, 0.12, math.pi / 4, 0.58, 0.2])

    def is_valid_placement(self, p):
        p = np.asarray(p)
        lo, hi = self.placement_space.low, self.placement_space.high
        return bool(np.all(p >= lo - 1e-9) and np.all(p <= hi + 1e-9) and np.linalg.norm(p[3:5] - p[:2]) >= 0.1)


def test_fps_centre_sequence_starts_at_the_centre_and_spreads_position_and_yaw():
    env = _FakePushEnv()
    lo, hi = env.placement_space.low, env.placement_space.high
    seq = PlacementSequence(env, "fps-centre", seed=0, fps_pool=300)
    first = seq[0]
    np.testing.assert_allclose(first[:3], ((lo + hi) / 2)[:3])  # the centre of x, y, yaw
    assert env.is_valid_placement(first)  # the target (centre invalid there) drawn until valid
    spread = (np.array([seq[i] for i in range(1, 9)])[:, :3] - lo[:3]) / (hi - lo)[:3]
    assert np.all(np.abs(spread - 0.5).max(axis=1) > 0.35)  # the next ones near the faces of the (x, y, yaw) box
    assert {bool(s) for s in spread[:, 2] > 0.5} == {True, False}  # both signs of yaw
    again = PlacementSequence(env, "fps-centre", seed=0, fps_pool=300)
    np.testing.assert_array_equal(np.array([again[i] for i in range(9)]), np.array([seq[i] for i in range(9)]))
    # the target is drawn at random even where the centre of its range would be valid (demos at the range's edges
    # and test cells near its centre then get targets from one distribution), the object kept
    far = [complete_placement(env, np.array([0.54, 0.12, 0.0, 0.0, 0.0]), (0, 1, 2), np.random.default_rng(k))
           for k in range(200)]  # fmt: skip
    assert all(env.is_valid_placement(p) for p in far)
    np.testing.assert_allclose(np.array(far)[:, :3], np.tile([0.54, 0.12, 0.0], (200, 1)))
    targets = np.array(far)[:, 3:]
    assert len(np.unique(targets.round(9), axis=0)) == 200
    # uniform over the valid targets: about as often in each half of the target's x and y range
    mid = (lo + hi)[3:] / 2
    assert 0.3 < np.mean(targets[:, 0] < mid[0]) < 0.7 and 0.3 < np.mean(targets[:, 1] < mid[1]) < 0.7


def test_panda_grid_varies_x_y_and_yaw_in_at_least_25_cells(tmp_path):
    _needs_panda()
    a = cli.parse_args(["--suite", "panda", "--scale", "cpu", "--protocol", "spatial", "--tasks", "push-block",
                        "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    es = Benchmark(a).eval_set("push-block")
    P = np.asarray(es["placements"])
    assert len(P) >= 25 and len(P) + es["n_invalid"] == 27 and es["grid_dims"] == [0, 1, 2]
    for d in (0, 1, 2):
        assert len(np.unique(P[:, d].round(6))) == 3  # x, y and yaw each take three values
    assert np.ptp(P[:, 2]) > math.radians(50)  # yaw from -30 to +30 degrees
    assert sorted(map(tuple, es["cells"])) == sorted({(c[0], c[1], c[2]) for c in es["cells"]})  # distinct cells
    assert es["other_coordinates"] == "seeded" and len(es["other_seeds"]) == len(P)
    # deterministic: the same grid again
    assert Benchmark(a).eval_set("push-block")["placements"] == es["placements"]


def test_grid_axis_layouts():
    assert grid_axis(0.0, 1.0, 3, "edges") == [0.0, 0.5, 1.0]
    np.testing.assert_allclose(grid_axis(0.0, 1.0, 4, "cells"), [0.125, 0.375, 0.625, 0.875])
    with pytest.raises(ValueError):
        grid_axis(0.0, 1.0, 3, "corners")


def test_a_3d_grid_skips_invalid_cells_and_counts_them():
    env = _FakePushEnv()
    lo, hi = env.placement_space.low, env.placement_space.high
    g = grid_placements(env, "push-block", lo, hi, 3, [0, 1, 2], 1000, n_third=3, layout="edges", others="centre")
    # target at its centre (0.45, 0): invalid for the three block positions within 10 cm of it, at every yaw
    assert len(g["placements"]) + g["n_invalid"] == 27 and g["n_invalid"] == 9
    assert all(len(c) == 3 for c in g["cells"])


# ---------------------------------------------------------------------------------------------- heat maps
def _fake_3d_results() -> dict:
    yaws = [-math.pi / 6, 0.0, math.pi / 6]
    xs, ys = [0.39, 0.45, 0.51], [-0.08, 0.0, 0.08]
    cells, placements = [], []
    for iz, z in enumerate(yaws):
        for iy, y in enumerate(ys):
            for ix, x in enumerate(xs):
                if (iz, iy, ix) == (1, 1, 1):
                    continue  # an invalid cell
                cells.append([iy, ix, iz])
                placements.append([x, y, z, 0.45, 0.15])
    runs = []
    for m in ("rnd_ai", "act"):
        succ = [iz == 0 for _, _, iz in cells] if m == "rnd_ai" else [ix == 2 for _, ix, _ in cells]
        runs.append({"method": m, "task": "push-block", "demos": 2, "seed": 0, "eval_episodes": len(succ),
                     "successes": sum(succ), "per_episode_success": succ})  # fmt: skip
    return {
        "benchmark": {"scale": "cpu", "suite": "panda", "protocol": "spatial", "tasks": ["push-block"], "demos": [2],
                      "methods": ["rnd_ai", "act"]},
        "eval_sets": {"push-block": {"grid_dims": [0, 1, 2], "grid_x": xs, "grid_y": ys, "grid_z": yaws,
                                     "cells": cells, "placements": placements, "n_invalid": 1}},
        "datasets": {"push-block": {"2": {"placements": [[0.45, 0.0, 0.0, 0.53, 0.16], [0.37, 0.11, -0.76, 0.45, 0.0]]}}},
        "runs": runs,
    }  # fmt: skip


def test_3d_heat_map_draws_one_xy_map_per_yaw(tmp_path):
    res = _fake_3d_results()
    titles = reports.plot_heatmap_3d(res, "push-block", tmp_path / "heat.png")
    assert (tmp_path / "heat.png").stat().st_size > 5000
    assert len(titles) == 2 * 3  # methods x yaws (one demo count)
    assert titles[0] == "R&D-AI, 2 demos, yaw -30°: 100% of 9"  # R&D-AI succeeds at -30 degrees only
    assert titles[1] == "R&D-AI, 2 demos, yaw +0°: 0% of 8"  # the invalid centre cell is not counted
    assert titles[5] == "ACT, 2 demos, yaw +30°: 33% of 9"
    reports.plot_heatmap(res, "push-block", tmp_path / "via_dispatch.png")  # plot_heatmap hands 3-D grids over
    assert (tmp_path / "via_dispatch.png").exists()


def test_3d_heat_map_of_push_block_draws_each_cells_direction_to_its_target(tmp_path):
    """The target differs per cell (drawn at random): the map shows where each cell pushes, so two result sets that
    differ only in their targets give different pictures, and a lift-cube set with the same numbers draws none."""
    import matplotlib.image as mpimg

    res = _fake_3d_results()
    reports.plot_heatmap_3d(res, "push-block", tmp_path / "a.png")
    other = _fake_3d_results()
    other["eval_sets"]["push-block"]["placements"] = [[*p[:3], p[0], p[1] - 0.15]
                                                      for p in other["eval_sets"]["push-block"]["placements"]]  # fmt: skip
    reports.plot_heatmap_3d(other, "push-block", tmp_path / "b.png")
    a, b = mpimg.imread(tmp_path / "a.png"), mpimg.imread(tmp_path / "b.png")
    assert a.shape == b.shape and np.abs(a - b).max() > 0.5  # arrows pointing elsewhere
    lift = _fake_3d_results()
    lift["eval_sets"]["lift-cube"] = lift["eval_sets"].pop("push-block")
    lift["datasets"]["lift-cube"] = lift["datasets"].pop("push-block")
    for r in lift["runs"]:
        r["task"] = "lift-cube"
    lift["benchmark"]["tasks"] = ["lift-cube"]
    reports.plot_heatmap_3d(lift, "lift-cube", tmp_path / "c.png")
    lift["eval_sets"]["lift-cube"]["placements"] = [p[:3] for p in lift["eval_sets"]["lift-cube"]["placements"]]
    reports.plot_heatmap_3d(lift, "lift-cube", tmp_path / "d.png")  # 3-number placements: nothing to point at
    c, d = mpimg.imread(tmp_path / "c.png"), mpimg.imread(tmp_path / "d.png")
    assert np.array_equal(c, d)
    # slide-block's 3-number placements imply their target (10 cm along the block's +y): arrows are drawn
    slide = json.loads(json.dumps(lift).replace("lift-cube", "slide-block"))
    slide["datasets"]["slide-block"]["2"]["placements"] = [p[:3] for p in slide["datasets"]["slide-block"]["2"]["placements"]]
    reports.plot_heatmap_3d(slide, "slide-block", tmp_path / "e.png")
    assert np.abs(mpimg.imread(tmp_path / "e.png") - d).max() > 0.5


def test_a_reused_dataset_recorded_with_another_placement_rule_is_refused(tmp_path):
    """The benchmark reuses a complete dataset by name; one whose logged placements are not those the recorder
    draws today (push-block's former rule: the target at the centre of its range where valid) must not be
    trained on silently."""
    _needs_panda()

    from lerobot_rnd.sim.panda_env import RnDPandaEnv

    a = cli.parse_args(["--suite", "panda", "--scale", "cpu", "--protocol", "spatial", "--tasks", "push-block",
                        "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    env = RnDPandaEnv("push-block")
    try:
        seq = PlacementSequence(env, "fps-centre", seed=0)
        today = [seq[i] for i in range(3)]
    finally:
        env.close()
    settings = {"task": "push-block", "placements": "fps-centre", "seed": 0, "fps_pool": 1000}

    def write(root, placements):
        (root / "meta").mkdir(parents=True)
        log = {"settings": settings, "attempts": [
            {"task": "push-block", "placement_index": i, "placement": [float(v) for v in p], "success": True,
             "episode_index": i} for i, p in enumerate(placements)]}  # fmt: skip
        (root / "meta" / "rnd_recording.json").write_text(json.dumps(log))
        return root

    Benchmark(a)._check_reused_placements("push-block", write(tmp_path / "same", today))  # passes
    old_rule = [np.r_[p[:3], 0.45, 0.0] if np.linalg.norm(p[:2] - [0.45, 0.0]) >= 0.1 else p for p in today]
    assert any(not np.allclose(o, t) for o, t in zip(old_rule, today, strict=True))
    with pytest.raises(RuntimeError, match="old.*remove"):
        Benchmark(a)._check_reused_placements("push-block", write(tmp_path / "old", old_rule))


def test_a_run_trained_on_other_placements_than_its_dataset_now_holds_is_not_resumed_or_collected(tmp_path):
    """A run remembers a fingerprint of its demos' and evaluation placements; when the dataset is recorded again
    (or the grid changes) its finished or part-done state must not be carried into the new results."""

    a = cli.parse_args(["--suite", "panda", "--scale", "cpu", "--protocol", "spatial", "--tasks", "push-block",
                        "--demos", "8", "--methods", "act", "--resume", "--out", str(tmp_path / "o"),
                        "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    b = Benchmark(a)
    demos = [[0.45, 0.0, 0.0, 0.53, 0.165], [0.36, 0.11, -0.76, 0.46, -0.03]]
    b.datasets = {"push-block": {8: {"placements": demos}}}
    b.eval_sets = {"push-block": {"placements": [[0.39, -0.08, -0.52, 0.5, 0.1]]}}
    rdir = b.run_dir("act", "push-block", 8, 0)
    rdir.mkdir(parents=True)
    (rdir / "run.json").write_text(json.dumps({"status": "failed", "inputs_sha1": b.inputs_sha1("push-block", 8)}))
    b.run_one("act", "push-block", 8, 0)  # the same inputs: its state is used (a failed run is left alone)
    assert b.failed
    # the demos 1e-12 apart are the same placements; another target is not
    b.datasets["push-block"][8]["placements"] = [[v + 1e-12 for v in p] for p in demos]
    b.run_one("act", "push-block", 8, 0)
    b.datasets["push-block"][8]["placements"] = [demos[0], [0.36, 0.11, -0.76, 0.45, 0.0]]
    with pytest.raises(SystemExit, match="other placements.*move"):
        b.run_one("act", "push-block", 8, 0)


def test_demo_yaw_labels_of_nearby_demos_are_stacked_not_printed_over_each_other():
    """Hand-worked offsets (points): a label sits 3 points from its mark towards the middle of the map; each earlier
    mark within 8% of the map's width and height pushes it 6 points further away in y."""
    x = [0.10, 0.12, 0.90, 0.13, 0.50]
    y = [0.10, 0.11, 0.90, 0.10, 0.10]
    offsets = reports._label_offsets(x, y, [0.0, 1.0, 0.0, 1.0])
    assert offsets == [(3.0, 3.0), (3.0, 9.0), (-3.0, -3.0), (3.0, 15.0), (3.0, 3.0)]


def test_results_md_says_how_many_episodes_each_cell_has():
    """results.md's settings line: a count under the random protocol, one episode per grid point under the spatial
    one (results.json stores that as the phrase 'one per valid grid point')."""
    assert reports._episodes_per_cell({"eval_episodes_per_cell": 50}) == "50 episodes per cell"
    assert reports._episodes_per_cell({"eval_episodes_per_cell": "one per valid grid point"}) == (
        "one episode per valid grid point")
