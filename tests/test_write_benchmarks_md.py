"""benchmarks/write_benchmarks_md.py: the success-by-distance table counts episodes by hand-placed goals."""

from __future__ import annotations

from benchmarks.write_benchmarks_md import generalisation_section


def test_success_by_distance_to_the_nearest_demo_goal():
    def placement(goal_xyz):  # reach-v3: [object xyz, goal xyz]; the object must not count
        return [0.5, 0.5, 0.5, *goal_xyz]

    train = [placement([0.0, 0.8, 0.1]), placement([0.1, 0.8, 0.1])]
    # nearest demo goal at 1 cm, 5 cm (3-4-5 triangle), 7 cm and 30 cm
    evals = [placement([0.01, 0.8, 0.1]), placement([0.13, 0.84, 0.1]), placement([0.0, 0.8, 0.17]),
             placement([0.0, 0.8, 0.4])]  # fmt: skip
    res = {
        "eval_sets": {"reach-v3": {"placements": evals}},
        "datasets": {"reach-v3": {"10": {"placements": train}}},
        "runs": [{"task": "reach-v3", "label": "R&D-AI", "demos": 10, "per_episode_success": [True, True, False, True]},
                 {"task": "drawer-close-v3", "label": "R&D-AI", "demos": 10, "per_episode_success": [True]}],
    }  # fmt: skip
    lines = generalisation_section(res, "cpu")
    assert "| R&D-AI | 10 | 1/1 | 1/1 | 0/1 | 1/1 |" in lines
    assert sum(line.startswith("| R&D-AI") for line in lines) == 1  # drawer-close has no goal to measure


def test_each_train_step_json_gets_its_own_section_naming_its_file_and_cpu():
    from benchmarks.write_benchmarks_md import train_step_section

    def result(method, total, data=0.05):
        phases = {"data": data, "pre": 0.0, "render": 0.1, "forward": 0.2, "backward": total - 0.35 - data, "optim": 0.0}
        return {"method": method, "parameters": 6e6, "median_s": phases, "median_total_s": total,
                "speedup_vs_reference": 0.0}  # fmt: skip

    res = {"command": "python benchmarks/bench_train_step.py", "steps": 5, "warmup": 2, "batch_size": 8,
           "threads": 2, "reference": "old", "results": [result("old", 4.05), result("new", 0.45)],
           "machine": {"cores": 2, "torch": "2.10", "cpu_capability": "AVX2"}}  # fmt: skip
    lines = train_step_section(res, "train_step_cpu_avx2.json")
    text = "\n".join(lines)
    assert "train_step_cpu_avx2.json" in text and "AVX2" in lines[0]
    new_row = next(line for line in lines if line.startswith("| `new`"))
    assert "0.400 (10.0x)" in new_row  # model step without data: (4.05 - 0.05) / (0.45 - 0.05)


def test_ablation_rows_show_the_patch_embedding_and_precision_they_ran_with():
    from benchmarks.write_benchmarks_md import ablation_section

    row = {"name": "ema", "train": "--policy.use_ema=true", "sampler": "(config defaults)", "steps": 3000,
           "final_loss": 0.03, "success_rate": 0.5, "ci95": [0.3, 0.7], "episodes": 20,
           "trained_switches": {"patch_embed": "conv"}, "bf16_autocast_on_this_cpu": False}  # fmt: skip
    old = {k: v for k, v in row.items() if k not in ("trained_switches", "bf16_autocast_on_this_cpu")}
    lines = ablation_section({"rows": [row, {**old, "name": "old"}]}, "x.json")
    assert any(line.startswith("| ema |") and "| conv | float32 |" in line for line in lines)
    assert any(line.startswith("| old |") and "| – | – |" in line for line in lines)


def test_ablation_rows_show_the_demos_cameras():
    from benchmarks.write_benchmarks_md import ablation_section

    row = {"name": "c2top", "train": "(config defaults)", "sampler": "(config defaults)", "steps": 3000,
           "final_loss": 0.03, "success_rate": 0.5, "ci95": [0.3, 0.7], "episodes": 20,
           "demos_cameras": ["corner2", "topview"]}  # fmt: skip
    old = {k: v for k, v in row.items() if k != "demos_cameras"}  # rows written before cameras were recorded
    lines = ablation_section({"rows": [row, {**old, "name": "old"}]}, "x.json")
    assert any(line.startswith("| c2top |") and "| corner2 + topview |" in line for line in lines)
    assert any(line.startswith("| old |") and "| corner2 + behindGripper |" in line for line in lines)


def test_ablation_rows_show_how_many_demos_they_trained_on():
    from benchmarks.write_benchmarks_md import ablation_section

    row = {"name": "n20", "train": "(config defaults)", "sampler": "(config defaults)", "steps": 3000,
           "final_loss": 0.03, "success_rate": 0.5, "ci95": [0.3, 0.7], "episodes": 20, "demos": 20}  # fmt: skip
    old = {k: v for k, v in row.items() if k != "demos"}  # rows written before the count was recorded: 10 demos
    lines = ablation_section({"rows": [row, {**old, "name": "old"}]}, "x.json")
    assert any(line.startswith("| n20 | 20 |") for line in lines)
    assert any(line.startswith("| old | 10 |") for line in lines)


def test_ablation_rows_show_how_long_the_demos_go_on_after_success():
    from benchmarks.write_benchmarks_md import ablation_section

    row = {"name": "settle", "train": "(config defaults)", "sampler": "(config defaults)", "steps": 3000,
           "final_loss": 0.03, "success_rate": 0.5, "ci95": [0.3, 0.7], "episodes": 20, "demos": 10,
           "demos_expert_reach_target": "tcp", "demos_extra_steps": 40}  # fmt: skip
    old = {k: v for k, v in row.items() if k != "demos_extra_steps"}  # recorded before: the default, 10
    lines = ablation_section({"rows": [row, {**old, "name": "old"}]}, "x.json")
    head = next(line for line in lines if line.startswith("| row |")).split(" | ")
    col = head.index("frames after success")
    assert next(line for line in lines if line.startswith("| settle |")).split(" | ")[col] == "40"
    assert next(line for line in lines if line.startswith("| old |")).split(" | ")[col] == "10"


def test_a_folder_of_collected_runs_says_so_and_links_its_sources():
    import json
    from pathlib import Path

    import benchmarks.write_benchmarks_md as w

    res = json.loads((Path(w.RESULTS) / "cpu_3000_drawer" / "results.json").read_text())
    trained = "\n".join(w.cpu_benchmark_section(res, "trained_here", "trained_here"))
    src = "benchmarks/results/{}/runs/{}__drawer-close-v3__n10__seed0.json"
    runs = [{**r, "collected_from": src.format("cpu_3000_drawer" if r["method"] != "act" else "other", r["method"])}
            for r in res["runs"]]  # fmt: skip
    collected = "\n".join(w.cpu_benchmark_section({**res, "runs": runs}, "collected", "collected"))
    partly = "\n".join(w.cpu_benchmark_section({**res, "runs": [runs[0], *res["runs"][1:]]}, "partly", "partly"))
    assert "trains nothing" not in trained and "collect-from" not in trained
    assert "This folder trains nothing: 3 runs are read from [`cpu_3000_drawer`]" in collected
    assert "[`other`](../benchmarks/results/other/)" in collected
    assert "This folder trains 2 of its runs: 1 run is read from" in partly


def test_a_benchmark_with_two_demo_counts_shows_success_against_demos():
    import json
    from pathlib import Path

    import benchmarks.write_benchmarks_md as w

    res = json.loads((Path(w.RESULTS) / "cpu_3000_drawer" / "results.json").read_text())
    one = "\n".join(w.cpu_benchmark_section(res, "x", "x"))
    two = "\n".join(w.cpu_benchmark_section({**res, "benchmark": {**res["benchmark"], "demos": [10, 20]}}, "x", "x"))
    assert "success_vs_demos" not in one
    assert "![success against the number of demos](images/x_success_vs_demos.png)" in two


def test_runs_that_share_a_note_share_its_footnote():
    """The camera-mismatch folder's three runs carry one note: it is printed once, and each run points at it."""
    import json
    from pathlib import Path

    import benchmarks.write_benchmarks_md as w

    res = json.loads((Path(w.RESULTS) / "cpu_3000_reach_n20_camera_mismatch" / "results.json").read_text())
    lines = w.cpu_benchmark_section(res, "cpu_3000_reach_n20_camera_mismatch", "x")
    footnotes = [line for line in lines if line.startswith("[")]
    assert len(footnotes) == 1 and footnotes[0].startswith("[1] Evaluated with another corner2 pose")
    rows = [line for line in lines if line.startswith("| ") and "reach-v3" in line]
    assert len(rows) == 3 and all(" [1] |" in row for row in rows)
