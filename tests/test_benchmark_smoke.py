"""benchmarks/run_benchmark.py and its package benchmarks/harness/: statistics and reports (fast), the commands
it would run (fast, dry run), and the whole pipeline at smoke scale with a stop-and-resume (slow: minutes of
training and MuJoCo evaluation)."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.harness import cli, reports, scales
from benchmarks.harness.runs import Benchmark

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "run_benchmark.py"


def test_the_entry_point_keeps_the_names_imported_from_it():
    spec = importlib.util.spec_from_file_location("run_benchmark", SCRIPT)
    rb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rb)
    assert rb.main is cli.main and rb.parse_args is cli.parse_args and rb.Benchmark is Benchmark
    assert rb.wilson_interval is reports.wilson_interval and rb.METHODS is scales.METHODS
    assert all(hasattr(rb, name) for name in rb.__all__)


def test_wilson_interval():
    assert reports.wilson_interval(0, 50)[0] == 0.0 and reports.wilson_interval(50, 50)[1] == 1.0
    assert math.isnan(reports.wilson_interval(0, 0)[0])
    lo, hi = reports.wilson_interval(0, 2)
    assert lo == 0.0 and hi == pytest.approx(0.6576, abs=1e-3)
    lo, hi = reports.wilson_interval(25, 50)
    assert lo == pytest.approx(0.3664, abs=1e-3) and hi == pytest.approx(0.6336, abs=1e-3)
    lo, hi = reports.wilson_interval(50, 50)
    assert hi == 1.0 and lo == pytest.approx(0.9287, abs=1e-3)


def _fake_results(tmp_path: Path) -> dict:
    runs = []
    rates = {"rnd_ai": (40, 45), "act": (48, 30), "diffusion": (10, 20)}  # successes of 50 at 10 / 20 demos
    for m, ks in rates.items():
        for n, k in zip((10, 20), ks, strict=True):
            succ = [True] * k + [False] * (50 - k)
            lo, hi = reports.wilson_interval(k, 50)
            runs.append({"method": m, "label": scales.METHODS[m][1], "task": "reach-v3", "demos": n, "seed": 0,
                         "protocol": "random", "status": "done", "steps": 100, "batch_size": 8, "steps_done": 100,
                         "n_params": 1_000_000, "train_seconds": 10.0, "train_wall_seconds": 20.0,
                         "train_slices": [], "eval_episodes": 50, "eval_episodes_planned": 50, "successes": k,
                         "success_rate": k / 50, "ci95": [lo, hi], "eval_seconds": 5.0,
                         "per_episode_success": succ, "eval_seeds": list(range(1000, 1050)),
                         "checkpoint": None, "run_dir": "x", "commands": {}, "error": None})  # fmt: skip
    return {
        "benchmark": {"scale": "gpu", "protocol": "random", "tasks": ["reach-v3"], "demos": [10, 20],
                      "methods": list(rates), "seeds": [0], "device": "cuda", "complete": True,
                      "written": "now", "host": {"platform": "p", "cpus": 2, "cuda": None, "torch": "t",
                                                 "lerobot": "0.4.4"}},
        "settings": {"matched": {"steps": 100, "batch_size": 8}, "record_seed": 0, "eval_seed": 1000,
                     "eval_episodes_per_cell": 50, "episode_length": 300, "eval_placements": "seeded",
                     "method_args": {m: [] for m in rates},
                     "config_files": {m: f"policies_config/metaworld/{m}.json" for m in rates}},
        "datasets": {}, "eval_sets": {}, "runs": runs, "rnd_losses": reports.rnd_losses(runs),
    }  # fmt: skip


def test_reports_from_results(tmp_path):
    res = _fake_results(tmp_path)
    losses = res["rnd_losses"]
    # ACT beats R&D-AI at 10 demos (48 vs 40 of 50: intervals overlap), nobody beats it at 20 demos
    assert [(x["demos"], x["baseline"], x["significant"]) for x in losses] == [(10, "act", False)]
    md = reports.markdown_report(res)
    assert "| R&D-AI | 80% [67–89] (40/50) | 90% [79–96] (45/50) | 85% [77–91] (85/100) |" in md
    assert "Where R&D loses" in md and "ACT 96% > R&D-AI 80% (within the intervals)" in md
    reports.plot_success_vs_demos(res, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").stat().st_size > 1000


def test_the_mean_bar_carries_the_pooled_interval_of_the_three_tasks(tmp_path):
    # the 3,000-step CPU table: R&D-AI 50/50 drawer, 47/50 button, 26/50 reach -> 123/150, Wilson 75.1-87.3 %
    res = _fake_results(tmp_path)
    proto = next(r for r in res["runs"] if r["method"] == "rnd_ai")
    tasks = {"drawer-close-v3": 50, "button-press-topdown-v3": 47, "reach-v3": 26}
    res["runs"] = [dict(proto, task=t, demos=10, successes=k) for t, k in tasks.items()]
    res["runs"].append(dict(proto, method="act", task="reach-v3", demos=10, successes=29))  # ACT lacks two tasks
    res["benchmark"].update(tasks=list(tasks), demos=[10], methods=["rnd_ai", "act"])
    panels, bars = reports.success_bars(res)
    assert panels == [*tasks, "mean over tasks"]
    mean = dict(bars["rnd_ai"])[3]
    assert (mean["k"], mean["n"]) == (123, 150)
    assert mean["lo"] == pytest.approx(0.7508, abs=1e-3) and mean["hi"] == pytest.approx(0.8732, abs=1e-3)
    assert [i for i, _ in bars["act"]] == [2]  # no mean bar for a method that lacks a task
    reports.plot_success_per_task(res, tmp_path / "bars.png")
    assert (tmp_path / "bars.png").stat().st_size > 1000


def test_the_plots_legend_lists_runs_that_only_an_earlier_panel_shows(tmp_path):
    # the Panda spatial folder once had ACT and R&D-AI only on lift-cube (first panel) and R&D-AI n2 only on
    # push-block (last panel): the legend, taken from the last panel, named only "R&D-AI (n2, s0)"
    res = _fake_results(tmp_path)
    proto = next(r for r in res["runs"] if r["method"] == "rnd_ai")
    curve = [[50, 1.0], [100, 0.5]]
    res["runs"] = [dict(proto, method="rnd_ai", task="lift-cube", demos=8, loss_curve=curve),
                   dict(proto, method="act", task="lift-cube", demos=8, loss_curve=curve),
                   dict(proto, method="rnd_ai", task="push-block", demos=2, loss_curve=curve)]  # fmt: skip
    res["benchmark"].update(tasks=["lift-cube", "push-block"], demos=[2, 8], methods=["rnd_ai", "act"])
    assert reports.plot_loss_curves(res, tmp_path / "loss.png") == ["R&D-AI (n8, s0)", "ACT (n8, s0)",
                                                                    "R&D-AI (n2, s0)"]  # fmt: skip
    assert reports.plot_success_vs_demos(res, tmp_path / "demos.png") == ["R&D-AI", "ACT"]
    res["runs"] = res["runs"][1:2]  # ACT only, on the first panel
    assert reports.plot_success_vs_demos(res, tmp_path / "demos.png") == ["ACT"]


def _dry_run(tmp_path, *extra):
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--scale", "smoke", "--out", str(tmp_path / "out"),
         "--work-dir", str(tmp_path / "work"), "--data-dir", str(tmp_path / "data"), "--dry-run", *extra],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    return [line[2:] for line in out.stdout.splitlines() if line.startswith("$ ")]


def test_dry_run_commands(tmp_path):
    cmds = _dry_run(tmp_path)
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    train = [c for c in cmds if "lerobot-train" in c]
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert len(rec) == 1 and len(train) == 5 and len(ev) == 5
    assert "--seed 0" in rec[0]
    for c in train:
        assert "--policy.push_to_hub=false" in c and "--steps=2" in c and "--seed=0" in c
    act = next(c for c in train if "act.json" in c)
    assert "--policy.pretrained_backbone_weights=null" in act and "--policy.chunk_size=8" in act
    dp = next(c for c in train if "diffusion.json" in c)
    assert "--policy.horizon=12" in dp and "--policy.down_dims=[32,64]" in dp
    for c in ev:
        assert "--seed=1000" in c and "--env.type=rnd_mw" in c and "--eval.n_episodes=2" in c


def _checkpoint(tmp_path, method: str, step: int) -> None:
    """A saved checkpoint of `method`'s smoke run at `step`, with the training state lerobot-train writes."""
    ckpt = tmp_path / "work" / "runs" / "random" / method / "reach-v3" / "n3" / "seed0" / "train" / "checkpoints"
    (ckpt / f"{step:06d}" / "pretrained_model").mkdir(parents=True)
    (ckpt / f"{step:06d}" / "training_state").mkdir()
    (ckpt / f"{step:06d}" / "training_state" / "training_step.json").write_text(json.dumps({"step": step}))
    (ckpt / "last").symlink_to(f"{step:06d}")



def test_a_harness_killed_mid_slice_keeps_the_cost_of_the_steps_it_checkpointed(tmp_path, monkeypatch):
    """A session that ends kills the harness mid-slice: the run resumes from its last checkpoint, and the steps
    before it once vanished from the run's cost (a 6,000-step run's JSON counted only its last 4,000 steps).
    Each checkpoint now records the slice so far; a slice that ends replaces that record with its own."""
    import time

    from benchmarks.harness import processes
    from benchmarks.harness import runs as harness_runs

    a = cli.parse_args(["--scale", "smoke", "--methods", "act", "--steps", "4", "--save-freq", "2",
                        "--out", str(tmp_path / "out"), "--work-dir", str(tmp_path / "work"),
                        "--data-dir", str(tmp_path / "data")])  # fmt: skip
    bench = Benchmark(a)
    rdir = bench.run_dir("act", "reach-v3", 3, 0)
    ckroot = rdir / "train" / "checkpoints"

    def save(step):  # what lerobot-train leaves at a checkpoint
        if (ckroot / "last").is_symlink():
            (ckroot / "last").unlink()
        _checkpoint(tmp_path, "act", step)

    class HarnessKilled(BaseException):
        pass

    def first_session(argv, log, deadline=None, poll=None, env=None, dry_run=False, marks=None):
        marks["train_loop_start"] = time.time()
        save(2)
        assert poll() is None
        raise HarnessKilled  # the session ends before step 4: nothing after this line runs

    monkeypatch.setattr(harness_runs, "run_logged", first_session)
    st: dict = {}
    with pytest.raises(HarnessKilled):
        bench.train("act", "reach-v3", 3, 0, st)
    killed = json.loads((rdir / "run.json").read_text())["train_slices"]
    assert [(s["start_step"], s["end_step"], s.get("provisional")) for s in killed] == [(0, 2, True)]
    assert killed[0]["loop_s"] >= 0 and killed[0]["wall_s"] >= killed[0]["loop_s"]

    def second_session(argv, log, deadline=None, poll=None, env=None, dry_run=False, marks=None):
        assert "--resume=true" in argv
        marks["train_loop_start"] = time.time()
        save(4)
        assert poll() is None
        return processes.ProcResult(rc=0, wall_s=0.5, marks=marks)

    monkeypatch.setattr(harness_runs, "run_logged", second_session)
    st = json.loads((rdir / "run.json").read_text())
    bench.train("act", "reach-v3", 3, 0, st)
    slices = json.loads((rdir / "run.json").read_text())["train_slices"]
    # The killed slice stays; the one that ended is recorded once, without the flag.
    assert [(s["start_step"], s["end_step"], s.get("provisional")) for s in slices] == [(0, 2, True), (2, 4, None)]
    assert slices[1]["rc"] == 0 and slices[1]["wall_s"] == 0.5

def test_eval_only_evaluates_only_runs_trained_to_the_end(tmp_path):
    """--eval-only collects what is trained: a run never trained is left for later, not marked failed (it once
    was, and results.md listed it as FAILED), and so is a run still training (it once was evaluated at its last
    checkpoint, part-way, and marked done)."""
    _checkpoint(tmp_path, "act", 2)  # the smoke scale trains 2 steps
    _checkpoint(tmp_path, "diffusion", 1)  # part-way
    cmds = _dry_run(tmp_path, "--methods", "rnd_ai,act,diffusion", "--eval-only")
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert not [c for c in cmds if "lerobot-train" in c]
    assert len(ev) == 1 and "/act/" in ev[0], ev
    for method in ("rnd_ai", "diffusion"):
        run = tmp_path / "work" / "runs" / "random" / method / "reach-v3" / "n3" / "seed0" / "run.json"
        assert not run.exists() or json.loads(run.read_text()).get("status") not in ("failed", "done")


def test_train_only_trains_and_leaves_the_evaluation_for_later(tmp_path):
    cmds = _dry_run(tmp_path, "--methods", "rnd_ai,act", "--train-only",
                    "--train-arg", "rnd:--policy.dim_model=384")  # fmt: skip
    train = [c for c in cmds if "lerobot-train" in c]
    assert len(train) == 2 and not [c for c in cmds if "lerobot-eval" in c]
    rnd = next(c for c in train if "rnd_ai" in c)
    assert "--policy.dim_model=384" in rnd
    assert "dim_model=384" not in next(c for c in train if "act.json" in c)
    with pytest.raises(SystemExit):
        cli.parse_args(["--scale", "smoke", "--train-only", "--eval-only"])



def test_image_size_reaches_the_recorder_and_rnd_and_names_its_own_datasets(tmp_path):
    cmds = _dry_run(tmp_path, "--methods", "rnd_ai,act", "--image-size", "192")
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 1 and "--image-size 192" in rec[0] and "mw_reach-v3_random_s0_n3_img192" in rec[0]
    train = [c for c in cmds if "lerobot-train" in c]
    assert all("--dataset.root=" in c and c.count("_img192") == 2 for c in train)  # repo id and root
    rnd, act = (next(c for c in train if f"/{m}/" in c) for m in ("rnd_ai", "act"))
    assert "--policy.image_size=[192,192]" in rnd and "--policy.image_size" not in act  # ACT takes them as recorded
    default = _dry_run(tmp_path / "default", "--methods", "rnd_ai")  # no flag: the datasets and commands of before
    assert not [c for c in default if "--image-size" in c or "--policy.image_size" in c or "_img" in c]
    assert any("--root " in c and c.split("--root ")[1].split()[0].endswith("mw_reach-v3_random_s0_n3") for c in default)


def test_resume_refuses_another_image_size(tmp_path):
    common = ["--scale", "smoke", "--methods", "act", "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"),
              "--data-dir", str(tmp_path / "d"), "--resume"]  # fmt: skip
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "state.json").write_text(json.dumps({"args": {"image_size": 192}}))
    b = Benchmark(cli.parse_args(common))  # the default size: checkpoints trained on 192-px images must not resume
    b.record = lambda task: (_ for _ in ()).throw(AssertionError("nothing may run"))
    with pytest.raises(SystemExit, match="pass the same --image-size"):
        b.run()
    with pytest.raises(SystemExit):
        cli.parse_args(["--scale", "smoke", "--image-size", "0"])

def test_extra_steps_reach_the_recorder_and_name_their_own_datasets(tmp_path):
    cmds = _dry_run(tmp_path, "--methods", "act", "--extra-steps", "40")
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 1 and "--extra-steps 40" in rec[0] and "mw_reach-v3_random_s0_n3_x40 " in rec[0]
    train = [c for c in cmds if "lerobot-train" in c]
    assert train and all(c.count("_x40") == 2 for c in train)  # repo id and root
    same = _dry_run(tmp_path / "ten", "--methods", "act", "--extra-steps", "10")  # the recorder's default: as before
    assert not [c for c in same if "--extra-steps" in c or "_x10" in c]
    common = ["--scale", "smoke", "--methods", "act", "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"),
              "--data-dir", str(tmp_path / "d"), "--resume"]  # fmt: skip
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "state.json").write_text(json.dumps({"args": {"extra_steps": 40}}))
    b = Benchmark(cli.parse_args(common))  # checkpoints trained on hold-at-goal demos must not resume on others
    b.record = lambda task: (_ for _ in ()).throw(AssertionError("nothing may run"))
    with pytest.raises(SystemExit, match="pass the same --extra-steps"):
        b.run()
    with pytest.raises(SystemExit):
        cli.parse_args(["--scale", "smoke", "--extra-steps", "-1"])


def test_dry_run_with_two_demo_counts_extends_the_smaller_dataset(tmp_path):
    """Used to crash: the dry run copied the smaller dataset, which it never records."""
    cmds = _dry_run(tmp_path, "--demos", "3,5", "--methods", "act")
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    assert len(rec) == 2 and "--episodes 5" in rec[1] and "--resume" in rec[1]
    assert any(c.startswith("cp -r ") and c.endswith("_n5") for c in cmds)
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").iterdir())


def test_spatial_grid_needs_two_varying_coordinates():
    import numpy as np

    from benchmarks.harness.grid_eval import grid_placements

    low, high = np.array([0.0, 0.9, 0.0]), np.array([0.0, 0.9, 0.1])  # one coordinate varies
    with pytest.raises(ValueError, match=r"two placement coordinates that vary; .* --grid-dims"):
        grid_placements(None, "drawer-close-v3", low, high, 3, None, 1000)


def test_eval_seeds_must_not_include_the_recording_seed(tmp_path):
    a = cli.parse_args(["--scale", "smoke", "--record-seed", "1001", "--out", str(tmp_path / "o"),
                       "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    with pytest.raises(ValueError, match="recording seed"):
        Benchmark(a).eval_set("reach-v3")


@pytest.mark.slow
def test_smoke_pipeline_with_resume(tmp_path):
    """Record 3 demos, train R&D-AI and ACT for 4 steps (stopped after the first checkpoint, then resumed),
    evaluate 1 episode each, and check results.json / results.md / the plot; a last call skips everything."""
    base = [sys.executable, str(SCRIPT), "--scale", "smoke", "--methods", "rnd_ai,act",
            "--out", str(tmp_path / "out"), "--work-dir", str(tmp_path / "work"),
            "--data-dir", str(tmp_path / "data"), "--steps", "4", "--save-freq", "2",
            "--eval-episodes", "1", "--episode-length", "10"]  # fmt: skip

    def call(*extra):
        return subprocess.run(base + list(extra), capture_output=True, text=True, timeout=1500, cwd=REPO)

    r = call("--stop-after-checkpoints", "1")
    assert r.returncode == 3, r.stdout[-3000:] + r.stderr[-3000:]
    r = call("--resume")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert res["benchmark"]["complete"]
    runs = {x["method"]: x for x in res["runs"]}
    assert set(runs) == {"rnd_ai", "act"}
    for x in runs.values():
        assert x["status"] == "done" and x["steps_done"] == 4 and x["eval_episodes"] == 1
        assert x["eval_seeds"] == [1000] and x["n_params"] > 0 and x["train_seconds"] > 0
        assert len(x["ci95"]) == 2
    assert [s["end_step"] for s in runs["rnd_ai"]["train_slices"]] == [2, 4]
    for method in ("rnd_ai", "act"):  # each evaluated episode keeps MetaWorld's max reward (how close it came)
        st = json.loads((tmp_path / "out" / "runs" / f"{method}__reach-v3__n3__seed0.json").read_text())
        assert [len(c["max_rewards"]) for c in st["eval_chunks"].values()] == [1]
        assert all(0.0 <= r <= 10.0 for c in st["eval_chunks"].values() for r in c["max_rewards"])
    assert "train_resume" in runs["rnd_ai"]["commands"]
    assert res["eval_sets"]["reach-v3"]["n_equal_to_a_train_placement"] == 0
    assert (tmp_path / "out" / "success_vs_demos.png").exists()
    assert "| R&D-AI |" in (tmp_path / "out" / "results.md").read_text()
    r = call("--resume")
    assert r.returncode == 0 and "lerobot-train" not in r.stdout


def test_cpu_scale_uses_the_cpu_configs(tmp_path):
    cmds = []
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--scale", "cpu", "--tasks", "reach-v3", "--methods", "rnd_ai,rnd_a,act,diffusion",
         "--out", str(tmp_path / "out"), "--work-dir", str(tmp_path / "work"), "--data-dir", str(tmp_path / "data"),
         "--dry-run"], capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    cmds = [line[2:] for line in out.stdout.splitlines() if line.startswith("$ ")]
    train = {c.split("--job_name=")[1].split("_reach")[0]: c for c in cmds if "lerobot-train" in c}
    assert "rnd_ai_cpu.json" in train["rnd_ai"] and "--policy.variant" not in train["rnd_ai"]
    assert "rnd_ai_cpu.json" in train["rnd_a"] and "--policy.variant=A" in train["rnd_a"]
    assert "act_cpu.json" in train["act"] and "diffusion_cpu.json" in train["diffusion"]
    assert all("--policy.device=cpu" in c and "--steps=2000" in c for c in train.values())
    ev = [c for c in cmds if "lerobot-eval" in c and "rnd_ai/" in c]
    assert len(ev) == 5 and "--seed=1000" in ev[0] and "--seed=1040" in ev[-1]  # 50 episodes in chunks of 10
    # LeRobot refuses a flag given twice, and DP's config must accept the horizon the harness passes (its U-Net
    # needs a multiple of 2 ** len(down_dims); 12 with the CPU config's 3 levels failed at the first step).
    for c in train.values():
        keys = [t.partition("=")[0] for t in c.split() if t.startswith("--")]
        assert len(keys) == len(set(keys)), c
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig

    dp_flags = dict(t[len("--policy."):].partition("=")[::2] for t in train["diffusion"].split() if t.startswith("--policy."))
    dp_json = json.loads((REPO / "policies_config" / "metaworld" / "diffusion_cpu.json").read_text())["policy"]
    DiffusionConfig(horizon=int(dp_flags.get("horizon", dp_json["horizon"])), down_dims=tuple(dp_json["down_dims"]),
                    n_obs_steps=int(dp_flags["n_obs_steps"]), n_action_steps=int(dp_flags["n_action_steps"]))


def test_override_flags_keeps_the_last_value_of_each_key():
    from benchmarks.harness.runs import override_flags

    assert override_flags(["--a=1", "--b=2", "--a=3", "--c"]) == ["--b=2", "--a=3", "--c"]


def test_a_committed_run_result_is_skipped_on_a_fresh_work_dir(tmp_path):
    """Each finished run's JSON under --out/runs survives a fresh clone (the work dir does not): a rerun skips
    it and reports it."""
    a = cli.parse_args(["--scale", "smoke", "--methods", "act", "--out", str(tmp_path / "o"),
                       "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    b = Benchmark(a)
    st = {"status": "done", "method": "act", "task": "reach-v3", "demos": 3, "seed": 0,
          "eval_chunks": {"0:2": {"successes": [True, False], "wall_s": 1.0, "dir": "x"}},
          "train_slices": [{"start_step": 0, "end_step": 2, "wall_s": 3.0, "loop_s": 2.0, "rc": 0, "stopped": None}],
          "loss_curve": [[1, 0.5], [2, 0.4]]}  # fmt: skip
    path = b.result_path("act", "reach-v3", 3, 0)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(st))

    def no_training(*args, **kwargs):
        raise AssertionError("a finished run must not be trained again")

    b.train = b.evaluate = no_training
    b.run_one("act", "reach-v3", 3, 0)
    runs = b.collect()
    assert runs[0]["status"] == "done" and runs[0]["successes"] == 1 and runs[0]["loss_curve"] == [[1, 0.5], [2, 0.4]]


def test_a_finished_runs_loss_curve_is_read_again_from_its_train_log(tmp_path):
    """A run finished before the log parser learned resumed invocations keeps a curve shifted past the last step;
    collecting it again reads the curve from the work dir's train.log (and leaves the rest of the run alone)."""
    a = cli.parse_args(["--scale", "smoke", "--methods", "act", "--out", str(tmp_path / "o"), "--log-freq", "1",
                       "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")])  # fmt: skip
    b = Benchmark(a)
    stale = [[1, 0.5], [2, 0.4], [5, 0.3], [6, 0.2]]  # resumed at 2 of 4, counted from the printed '5'
    st = {"status": "done", "method": "act", "task": "reach-v3", "demos": 3, "seed": 0, "loss_curve": stale,
          "eval_chunks": {"0:2": {"successes": [True, False], "wall_s": 1.0, "dir": "x"}}}  # fmt: skip
    path = b.result_path("act", "reach-v3", 3, 0)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(st))
    rdir = b.run_dir("act", "reach-v3", 3, 0)
    rdir.mkdir(parents=True)
    (rdir / "train.log").write_text(
        "$ lerobot-train\ncfg.steps=4 (4)\nTraining:   0%|  | 0/4 [00:00]\nstep:1 smpl:8 loss:0.5\nstep:2 smpl:8 loss:0.4\n"
        "$ lerobot-train --resume=true\ncfg.steps=4 (4)\nTraining:   0%|  | 0/2 [00:00]\nstep:5 smpl:8 loss:0.3\n"
        "step:6 smpl:8 loss:0.2\n"
    )
    b.train = b.evaluate = None  # a finished run is neither trained nor evaluated again
    b.run_one("act", "reach-v3", 3, 0)
    again = json.loads(path.read_text())
    assert again["loss_curve"] == [[1, 0.5], [2, 0.4], [3, 0.3], [4, 0.2]]
    assert again["eval_chunks"] == st["eval_chunks"] and again["status"] == "done"


def _source_folder(folder: Path, steps: int, successes: dict[str, int]) -> None:
    """A results folder as another benchmark leaves it: results.json (settings) and runs/<run>.json."""
    (folder / "runs").mkdir(parents=True)
    settings = {"matched": {"steps": steps, "batch_size": 4}, "record_seed": 0, "eval_seed": 1000,
                "episode_length": 50, "eval_episodes_per_cell": 2}  # fmt: skip
    (folder / "results.json").write_text(json.dumps({"benchmark": {"protocol": "random"}, "settings": settings}))
    for method, k in successes.items():
        st = {"status": "done", "method": method, "task": "reach-v3", "demos": 3, "seed": 0,
              "eval_chunks": {"0:2": {"successes": [True] * k + [False] * (2 - k), "wall_s": 1.0, "dir": "x"}}}
        (folder / "runs" / f"{method}__reach-v3__n3__seed0.json").write_text(json.dumps(st))


def test_collect_from_takes_finished_runs_from_other_folders_without_copying_them(tmp_path):
    _source_folder(tmp_path / "first", 10, {"act": 2})
    _source_folder(tmp_path / "second", 10, {"act": 0, "diffusion": 1})
    args = ["--scale", "smoke", "--methods", "act,diffusion,rnd_ai", "--tasks", "reach-v3", "--demos", "3",
            "--steps", "10", "--batch-size", "4", "--eval-episodes", "2", "--episode-length", "50",
            "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d"),
            "--collect-from", f"{tmp_path / 'first'},{tmp_path / 'second'}"]  # fmt: skip
    b = Benchmark(cli.parse_args(args))
    trained = []
    b.train = lambda method, *rest: trained.append(method)
    b.evaluate = lambda *rest: None
    for method in ("act", "diffusion", "rnd_ai"):
        b.run_one(method, "reach-v3", 3, 0)
    assert trained == ["rnd_ai"]  # only the run that no folder holds
    runs = {r["method"]: r for r in b.collect()}
    assert runs["act"]["successes"] == 2 and runs["act"]["collected_from"].endswith("first/runs/act__reach-v3__n3__seed0.json")
    assert runs["diffusion"]["successes"] == 1 and "/second/runs/" in runs["diffusion"]["collected_from"]
    assert runs["rnd_ai"]["collected_from"] is None
    assert not (tmp_path / "o" / "runs" / "act__reach-v3__n3__seed0.json").exists()  # nothing copied
    res = {"benchmark": {"scale": "smoke", "protocol": "random", "tasks": ["reach-v3"], "demos": [3],
                         "methods": ["act", "diffusion"], "seeds": [0], "complete": True, "written": "now",
                         "host": {"platform": "p", "cpus": 2, "cuda": None, "torch": "t", "lerobot": "0.4.4"}},
           "settings": {"matched": {"steps": 10, "batch_size": 4}, "record_seed": 0, "eval_seed": 1000,
                        "eval_episodes_per_cell": 2, "episode_length": 50, "eval_placements": "seeded",
                        "method_args": {}, "config_files": {}}, "runs": [runs["act"], runs["diffusion"]]}  # fmt: skip
    md = reports.markdown_report(res)
    assert "2 of the 2 runs were trained and evaluated by other benchmarks" in md and "first/runs/act__" in md


def test_collect_from_refuses_a_folder_trained_otherwise(tmp_path):
    _source_folder(tmp_path / "src", 3000, {"act": 2})
    args = ["--scale", "smoke", "--steps", "10", "--batch-size", "4", "--eval-episodes", "2", "--episode-length",
            "50", "--out", str(tmp_path / "o"), "--collect-from", str(tmp_path / "src")]  # fmt: skip
    with pytest.raises(SystemExit, match="its runs used matched.steps=3000, this benchmark steps=10"):
        Benchmark(cli.parse_args(args))
    with pytest.raises(SystemExit, match="not a benchmark results folder"):
        Benchmark(cli.parse_args([*args[:-1], str(tmp_path / "missing")]))


def test_resume_refuses_another_training_recipe(tmp_path):
    """A results folder holds one recipe: resuming a --train-arg run without it (or with another) is refused
    before anything runs, so a wider run is never reported as the plain config."""
    common = ["--scale", "smoke", "--methods", "act", "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"),
              "--data-dir", str(tmp_path / "d"), "--resume"]  # fmt: skip
    (tmp_path / "w").mkdir()
    first = cli.parse_args([*common, "--train-arg", "rnd:--policy.dim_model=384"])
    (tmp_path / "w" / "state.json").write_text(json.dumps({"args": {"train_arg": first.train_arg}}))
    b = Benchmark(cli.parse_args(common))
    b.record = lambda task: (_ for _ in ()).throw(AssertionError("nothing may run"))
    with pytest.raises(SystemExit, match="pass the same --train-arg"):
        b.run()


def _fake_recording(root, n: int, **settings):
    """A dataset folder as the harness reads it before training: LeRobot's episode count and the recorder's log."""
    (root / "meta").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps({"total_episodes": n, "total_frames": 10 * n}))
    attempts = [{"episode_index": i, "placement_index": i, "success": True,
                 "placement": [0.0, 0.6, 0.02, 0.01 * i, 0.85, 0.1]} for i in range(n)]  # fmt: skip
    (root / "meta" / "rnd_recording.json").write_text(json.dumps({
        "settings": {"suite": "metaworld", "task": "reach-v3", "cameras": ["corner2", "behindGripper"], **settings},
        "attempts": attempts}))  # fmt: skip


def test_demos_recorded_with_metaworlds_corner2_are_evaluated_with_it(tmp_path):
    """Used to be evaluated with the env's default (LeRobot's) corner2 pose: the policies saw another view of the
    scene than in their demos, and every method lost 6-10 of 50 reach episodes."""
    _fake_recording(tmp_path / "data" / "mw_reach-v3_random_s0_n3", 3, lerobot_corner2_pos=False)
    cmds = _dry_run(tmp_path, "--demos", "3", "--methods", "act")
    assert not [c for c in cmds if "lerobot-rnd-record" in c]
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert ev and all("--env.use_lerobot_corner2_pos=false" in c for c in ev)


def test_demos_recorded_with_the_defaults_are_evaluated_with_the_defaults(tmp_path):
    _fake_recording(tmp_path / "data" / "mw_reach-v3_random_s0_n3", 3, lerobot_corner2_pos=True)
    ev = [c for c in _dry_run(tmp_path, "--demos", "3", "--methods", "act") if "lerobot-eval" in c]
    assert ev and not [c for c in ev if "--env.use_lerobot_corner2_pos" in c or "--env.camera_names" in c]


def test_nested_demo_sets_recorded_with_different_cameras_are_refused(tmp_path):
    _fake_recording(tmp_path / "data" / "mw_reach-v3_random_s0_n3", 3, lerobot_corner2_pos=True)
    _fake_recording(tmp_path / "data" / "mw_reach-v3_random_s0_n5", 5, lerobot_corner2_pos=False)
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--scale", "smoke", "--out", str(tmp_path / "out"), "--demos", "3,5",
         "--methods", "act", "--work-dir", str(tmp_path / "work"), "--data-dir", str(tmp_path / "data"),
         "--dry-run"], capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert out.returncode != 0 and not [x for x in out.stdout.splitlines() if "lerobot-train" in x]
    err = out.stdout + out.stderr
    assert "recorded with different observations" in err and "use_lerobot_corner2_pos=false" in err


def test_grid_eval_builds_the_env_of_the_demos():
    """The grid evaluation's env, built from a recording's flags, shows corner2 from MetaWorld's own pose (read
    from a MetaWorld model the plugin never touched), and from LeRobot's pose without them."""
    import mujoco
    import numpy as np

    from benchmarks.harness.grid_eval import env_config
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv, make_metaworld_task_env
    from lerobot_rnd.sim.record import recorded_env_args

    untouched = make_metaworld_task_env("reach-v3").model
    metaworld_pos = untouched.cam_pos[mujoco.mj_name2id(untouched, mujoco.mjtObj.mjOBJ_CAMERA, "corner2")].copy()
    for settings, want in (({"lerobot_corner2_pos": False}, metaworld_pos), ({}, np.array([0.75, 0.075, 0.7]))):
        cfg = env_config("reach-v3", 20, recorded_env_args({"suite": "metaworld", **settings}))
        env = RnDMetaWorldEnv("reach-v3", observation_height=32, observation_width=32,
                              **{k: v for k, v in cfg.gym_kwargs.items() if k == "corner2_pos"})  # fmt: skip
        try:
            got = env.model.cam_pos[mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_CAMERA, "corner2")]
            np.testing.assert_allclose(got, want, atol=1e-9)
        finally:
            env.close()
    assert not np.allclose(metaworld_pos, [0.75, 0.075, 0.7])
    with pytest.raises(ValueError, match="--env"):
        env_config("reach-v3", 20, ["camera_names=[corner2]"])


def test_a_finished_collected_run_wins_over_an_unfinished_local_one(tmp_path):
    """A budget stop left a 'running' run.json here; another folder has since finished that run: it is collected,
    not trained again."""
    _source_folder(tmp_path / "other", 10, {"act": 1})
    args = ["--scale", "smoke", "--methods", "act", "--tasks", "reach-v3", "--demos", "3", "--steps", "10",
            "--batch-size", "4", "--eval-episodes", "2", "--episode-length", "50", "--out", str(tmp_path / "o"),
            "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d"),
            "--collect-from", str(tmp_path / "other")]  # fmt: skip
    b = Benchmark(cli.parse_args(args))
    local = b.run_dir("act", "reach-v3", 3, 0)
    local.mkdir(parents=True)
    (local / "run.json").write_text(json.dumps({"method": "act", "status": "running"}))
    trained = []
    b.train = lambda method, *rest: trained.append(method)
    b.evaluate = lambda *rest: None
    b.run_one("act", "reach-v3", 3, 0)
    assert trained == []
    (run,) = b.collect()
    assert run["successes"] == 1 and "/other/runs/" in run["collected_from"]


def test_multitask_dry_run_records_one_dataset_and_evaluates_every_task_in_one_call(tmp_path):
    cmds = _dry_run(tmp_path, "--multitask", "--tasks", "reach-v3,drawer-close-v3", "--methods", "rnd_ai,act")
    rec = [c for c in cmds if "lerobot-rnd-record" in c]
    train = [c for c in cmds if "lerobot-train" in c]
    ev = [c for c in cmds if "lerobot-eval" in c]
    assert len(rec) == 1 and len(train) == 2 and len(ev) == 2
    assert "--task reach-v3,drawer-close-v3 --episodes 3" in rec[0]
    root = rec[0].split("--root ")[1].split()[0]
    for c in train:
        assert f"--dataset.root={root}" in c and "--env.task=reach-v3,drawer-close-v3" in c
    for c in ev:
        assert "--env.task=reach-v3,drawer-close-v3" in c and "--eval.n_episodes=2" in c
    with pytest.raises(SystemExit):
        cli.parse_args(["--scale", "smoke", "--multitask", "--tasks", "reach-v3"])
    with pytest.raises(SystemExit):
        cli.parse_args(["--scale", "smoke", "--multitask", "--tasks", "reach-v3,push-v3", "--protocol", "spatial"])


def test_a_multitask_run_gives_one_row_per_task_and_counts_its_cost_once(tmp_path):
    a = cli.parse_args(["--scale", "smoke", "--multitask", "--tasks", "reach-v3,drawer-close-v3", "--methods", "act",
                        "--out", str(tmp_path / "o"), "--work-dir", str(tmp_path / "w"), "--data-dir",
                        str(tmp_path / "d")])  # fmt: skip
    b = Benchmark(a)
    unit = "reach-v3,drawer-close-v3"
    assert b.units == [unit]
    st = {"status": "done", "method": "act", "task": unit, "tasks": ["reach-v3", "drawer-close-v3"], "demos": 3,
          "seed": 0, "eval_chunks": {"0:2": {"successes": {"reach-v3": [True, True], "drawer-close-v3": [False, True]},
                                             "wall_s": 5.0, "dir": "x"}},
          "train_slices": [{"start_step": 0, "end_step": 2, "wall_s": 3.0, "loop_s": 2.0, "rc": 0, "stopped": None}],
          "loss_curve": [[1, 0.5], [2, 0.4]]}  # fmt: skip
    path = b.result_path("act", unit, 3, 0)
    assert path.name == "act__reach-v3+drawer-close-v3__n3__seed0.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(st))
    rows = b.collect()
    assert [(r["task"], r["successes"], r["eval_episodes"]) for r in rows] == [("reach-v3", 2, 2),
                                                                           ("drawer-close-v3", 1, 2)]
    assert all(r["training"] == "multi-task" and r["trained_on"] == ["reach-v3", "drawer-close-v3"] for r in rows)
    assert [r["train_seconds"] for r in rows] == [2.0, None] and [r["eval_seconds"] for r in rows] == [5.0, 0]
    assert rows[0]["loss_curve"] and rows[1]["loss_curve"] is None
    assert b.dataset_root(unit, 10)[1].startswith("local/mw_mt2-") and len(b.dataset_root(unit, 10)[1]) < 60


def _done_run(k: int, n: int) -> dict:
    return {"status": "done", "eval_chunks": {"0:2": {"successes": [True] * k + [False] * (n - k), "wall_s": 1.0,
                                                      "dir": "x"}}}  # fmt: skip


def test_resuming_a_subset_adds_its_runs_to_the_report_instead_of_replacing_it(tmp_path):
    """A call with --tasks / --demos / --methods narrower than the report in --out once rewrote results.json with
    that subset only; the report now keeps the earlier call's runs, datasets and evaluation placements, unless the
    earlier report was trained otherwise."""
    common = ["--scale", "smoke", "--steps", "10", "--batch-size", "4", "--out", str(tmp_path / "o"),
              "--work-dir", str(tmp_path / "w"), "--data-dir", str(tmp_path / "d")]  # fmt: skip
    out = tmp_path / "o"
    (out / "runs").mkdir(parents=True)
    earlier = {"benchmark": {"suite": "metaworld", "protocol": "random", "scale": "smoke", "multitask": False,
                             "tasks": ["drawer-close-v3", "reach-v3"], "demos": [3, 6], "methods": ["rnd_ai", "act"],
                             "seeds": [0], "command": "run_benchmark.py --tasks drawer-close-v3,reach-v3"},
               "settings": {"matched": {"steps": 10, "batch_size": 4}},
               "datasets": {"drawer-close-v3": {"3": {"root": "d/drawer3"}}},
               "eval_sets": {"drawer-close-v3": {"seeds": [1000, 1001], "placements": [[0], [1]]}}}  # fmt: skip
    (out / "results.json").write_text(json.dumps(earlier))
    (out / "runs" / "rnd_ai__drawer-close-v3__n6__seed0.json").write_text(json.dumps(_done_run(2, 2)))
    (out / "runs" / "act__reach-v3__n3__seed0.json").write_text(json.dumps(_done_run(1, 2)))
    b = Benchmark(cli.parse_args([*common, "--tasks", "reach-v3", "--demos", "3", "--methods", "act"]))
    assert b.report_axes() == (["drawer-close-v3", "reach-v3"], [3, 6], [0], ["rnd_ai", "act"])
    rows = {(r["method"], r["task"], r["demos"]): r for r in b.collect()}
    assert len(rows) == 2 * 2 * 2
    assert rows["rnd_ai", "drawer-close-v3", 6]["successes"] == 2  # the earlier call's run, kept
    assert rows["rnd_ai", "drawer-close-v3", 6]["eval_episodes_planned"] == 2  # with its evaluation placements
    assert rows["act", "reach-v3", 3]["successes"] == 1  # this call's run
    assert rows["act", "drawer-close-v3", 3]["status"] == "pending"
    assert b.datasets["drawer-close-v3"][3] == {"root": "d/drawer3"}
    assert b.earlier_commands() == ["run_benchmark.py --tasks drawer-close-v3,reach-v3"]
    # a report trained for another number of steps is not joined: this call's axes only
    other = Benchmark(cli.parse_args([*common[:2], "--steps", "20", *common[4:], "--tasks", "reach-v3", "--demos",
                                      "3", "--methods", "act"]))  # fmt: skip
    assert other.report_axes() == (["reach-v3"], [3], [0], ["act"]) and other.earlier_commands() == []


def test_report_dicts_follow_the_reports_task_order():
    from benchmarks.harness.runs import _in_order

    got = _in_order({"push": 1, "extra": 2, "lift": 3}, ["lift", "slide", "push"])
    assert list(got) == ["lift", "push", "extra"] and got == {"push": 1, "extra": 2, "lift": 3}
