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


def test_wilson_interval_matches_the_recorded_ones():
    """The page computes its intervals itself; they agree with those sampler_steps.py recorded."""
    import json

    import benchmarks.write_benchmarks_md as w

    res = json.loads((w.RESULTS / "one_step_sampling_test.json").read_text())
    for e in res["entries"]:
        lo, hi = w.wilson(e["successes"], e["episodes"])
        assert abs(lo - e["ci95"][0]) < 1e-9 and abs(hi - e["ci95"][1]) < 1e-9
    assert w.cell(26, 50) == "26/50 (39-65%)" and w.cell(0, 0) == "0/0 (0-100%)"


def test_headline_takes_rnd_from_one_step_sampling_and_baselines_from_their_runs():
    """R&D-AI's row is the shipped config's 1-step re-evaluation, not its benchmark runs' 4-step numbers."""
    import json

    import benchmarks.write_benchmarks_md as w

    res = json.loads((w.RESULTS / "one_step_sampling_test.json").read_text())
    lines = w.headline_section(res)
    rnd = next(line for line in lines if line.startswith("| R&D-AI"))
    act = next(line for line in lines if line.startswith("| ACT"))
    assert "**50/50** (93-100%)" in rnd and "**48/50** (87-99%)" in rnd and "| 26/50 (39-65%)" in rnd
    assert "47/50" not in rnd  # button-press with 4 steps
    assert "48/50 (87-99%)" in act and "38/50 (63-86%)" in act and "**29/50** (44-71%)" in act
    swapped = {**res, "entries": [{**e, "num_inference_steps": 5 - e["num_inference_steps"]} for e in res["entries"]]}
    assert "47/50" in next(line for line in w.headline_section(swapped) if line.startswith("| R&D-AI"))


def test_cost_is_a_ratio_to_act_in_the_same_run():
    import benchmarks.write_benchmarks_md as w

    def step(method, total):
        return {"method": method, "parameters": 1e6, "median_total_s": total, "speedup_vs_reference": 1.0,
                "median_s": {"data": 0.0, "pre": 0.0, "render": 0.0, "forward": total, "backward": 0.0, "optim": 0.0}}

    train = {"command": "c", "steps": 1, "warmup": 0, "batch_size": 8, "threads": 2, "reference": "act_cpu",
             "machine": {"cores": 2, "torch": "t", "cpu_capability": "AVX2"},
             "results": [step("rnd_ai_cpu", 0.5), step("act_cpu", 2.0), step("diffusion_cpu", 3.0)]}
    inference = {"machine": {"cpu_capability": "AVX512"},
                 "results": [{"method": "ACT", "config": "a", "params": 5e7, "median_ms": 40.0},
                             {"method": "R&D-AI", "config": "r", "params": 6e6, "median_ms": 60.0},
                             {"method": "Diffusion Policy", "config": "d", "params": 2.7e8, "median_ms": 400.0}]}  # fmt: skip
    lines = w.cost_section([("t.json", train)], ("i.json", inference))
    row = next(line for line in lines if line.startswith("| training step, AVX2"))
    assert "0.50 s (0.25x)" in row and "2.00 s (1.00x)" in row and "3.00 s (1.50x)" in row
    row = next(line for line in lines if line.startswith("| one action chunk, AVX512"))
    assert "60 ms (1.5x)" in row and "400 ms (10.0x)" in row


def test_the_page_and_the_archive_page_are_up_to_date():
    """docs/BENCHMARKS.md's generated block and ARCHIVE.md are what the JSON gives (run write_benchmarks_md.py)."""
    import benchmarks.write_benchmarks_md as w

    text = w.DOC.read_text()
    assert text.startswith("# Benchmarks\n\n" + w.START)  # the page opens with the current results
    assert w.render_doc(text) == text
    assert w.archive_page() == w.ARCHIVE_DOC.read_text()
    assert f"git tag `{w.TAG}` (commit `{w.TAG_COMMIT}`)" in text
    current, _, rest = text.partition("## Archived results")
    assert "archive/" not in current.split(w.START, 1)[1]  # nothing archived among the current results
    assert "one_step_sampling_test.json" in current and w.END in rest


def test_every_result_in_the_readme_is_a_current_one():
    """Each success cell of README.md's results table is in BENCHMARKS.md's generated (current) block."""
    import re

    import benchmarks.write_benchmarks_md as w

    readme = (w.REPO / "README.md").read_text()
    block = w.DOC.read_text().split(w.START, 1)[1].split("## Archived results", 1)[0].replace("**", "")
    cells = re.findall(r"\d+/\d+\*?\*? \(\d+-\d+%\)", readme)
    assert len(cells) >= 11
    for c in cells:
        assert c.replace("**", "") in block, c


def test_so101_section_reads_the_run_files_and_says_what_is_not_run(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    runs = tmp_path / w.SO101_FOLDER / "runs"
    runs.mkdir(parents=True)
    chunks = {"0": {"successes": [True, False, False, False, False]}, "1": {"successes": [True, True, False, False, False]}}
    (runs / "act__reach-target__n10__seed0.json").write_text(json.dumps({"status": "done", "eval_chunks": chunks}))
    (runs / "rnd_ai__pick-cube__n10__seed0.json").write_text(json.dumps({"status": "failed", "eval_chunks": chunks}))
    monkeypatch.setattr(w, "RESULTS", tmp_path)
    table = "\n".join(w.so101_section())
    assert "| method | reach-target, 10 demos | pick-cube, 10 demos |" in table  # no 20-demo run: no such column
    assert "| ACT | 3/10 (11-60%) | not run yet |" in table  # Wilson 95% for 3/10: 10.8-60.3%
    assert "| R&D-AI | not run yet | not run yet |" in table  # a failed run is no result
    (runs / "rnd_ai__reach-target__n20__seed0.json").write_text(json.dumps({"status": "done", "eval_chunks": chunks}))
    table = "\n".join(w.so101_section())
    assert "| method | reach-target, 10 demos | pick-cube, 10 demos | reach-target, 20 demos |" in table
    assert "| R&D-AI | not run yet | not run yet | 3/10 (11-60%) |" in table
    assert "| ACT | 3/10 (11-60%) | not run yet | not run yet |" in table


def test_panda_random_section_shows_only_finished_tasks(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)
    assert w.panda_random_section() == []  # nothing finished: no section
    runs = tmp_path / w.PANDA_RANDOM_FOLDER / "runs"
    runs.mkdir(parents=True)
    chunks = {"0:10": {"successes": [True] * 4 + [False] * 6}, "10:20": {"successes": [False] * 10}}
    (runs / "act__press-button__n10__seed0.json").write_text(json.dumps({"status": "done", "eval_chunks": chunks}))
    (runs / "rnd_ai__pick-place__n10__seed0.json").write_text(json.dumps({"status": "training", "eval_chunks": {}}))
    text = "\n".join(w.panda_random_section())
    assert "| method | press-button, 10 demos |" in text  # the unfinished pick-place run makes no column
    assert "| ACT | 4/20 (8-42%) |" in text  # Wilson 95% for 4/20: 8.1-41.6%
    assert "| R&D-AI | not run yet |" in text
    fit = {"rows": [{"method": "rnd_ai", "task": "press-button", "successes": 0, "episodes": 10},
                    {"method": "act", "task": "press-button", "successes": 8, "episodes": 10}]}  # fmt: skip
    (tmp_path / w.PANDA_RANDOM_FIT).write_text(json.dumps(fit))
    assert "R&D-AI press-button 0/10, ACT press-button 8/10" in "\n".join(w.panda_random_section())


def test_panda_spatial_section_shows_only_finished_cells_and_the_heat_maps_that_exist(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)
    assert w.panda_spatial_section() == []  # nothing finished: no section
    runs = tmp_path / w.PANDA_SPATIAL_FOLDER / "runs"
    runs.mkdir(parents=True)
    chunks = {"0:10": {"successes": [True] * 2 + [False] * 8}, "10:20": {"successes": [False] * 10},
              "20:27": {"successes": [True] + [False] * 6}}  # 3 of a 27-cell grid
    (runs / "rnd_ai__lift-cube__n8__seed0.json").write_text(json.dumps({"status": "done", "eval_chunks": chunks}))
    (runs / "act__lift-cube__n2__seed0.json").write_text(json.dumps({"status": "training", "eval_chunks": {}}))
    text = "\n".join(w.panda_spatial_section())
    assert "| method | lift-cube, 8 demos |" in text  # the unfinished 2-demo run makes no column
    assert "| R&D-AI | 3/27 (4-28%) |" in text  # Wilson 95% for 3/27: 3.9-28.1%
    assert "| ACT | not run yet |" in text and "heat maps" not in text
    (tmp_path / w.PANDA_SPATIAL_FOLDER / "heatmap_lift-cube.png").write_bytes(b"png")
    assert "heatmap_lift-cube.png" in "\n".join(w.panda_spatial_section())
    assert "success_vs_demos.png" not in "\n".join(w.panda_spatial_section())  # the harness has not drawn it
    (tmp_path / w.PANDA_SPATIAL_FOLDER / "success_vs_demos.png").write_bytes(b"png")
    assert f"![success against the number of demos, Wilson 95% intervals](../benchmarks/results/" \
           f"{w.PANDA_SPATIAL_FOLDER}/success_vs_demos.png)" in w.panda_spatial_section()


def test_few_demo_gap_sums_only_cells_both_methods_finished_with_at_most_8_demos(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)
    runs = tmp_path / w.PANDA_SPATIAL_FOLDER / "runs"
    runs.mkdir(parents=True)

    def run(name, k, n=27, status="done", folder=runs):
        chunk = {"0:27": {"successes": [True] * k + [False] * (n - k)}}
        (folder / f"{name}__seed0.json").write_text(json.dumps({"status": status, "eval_chunks": chunk}))

    columns = [("lift-cube", 2), ("lift-cube", 8), ("lift-cube", 16), ("push-block", 8)]
    cells = [(w.PANDA_SPATIAL_FOLDER, t, n) for t, n in columns]
    assert w.few_demo_gap(cells) == []  # nothing shared: no line
    run("rnd_ai__lift-cube__n2", 3)
    run("act__lift-cube__n2", 0)
    run("rnd_ai__lift-cube__n8", 21)
    run("act__lift-cube__n8", 4)
    run("rnd_ai__lift-cube__n16", 13)  # 16 demos: outside the condition
    run("act__lift-cube__n16", 27)
    run("rnd_ai__push-block__n8", 0)  # ACT's push-block run unfinished: the cell is not shared
    run("act__push-block__n8", 27, status="training")
    run("diffusion__lift-cube__n8", 9)
    lines = w.few_demo_gap(cells)
    # By hand: R&D-AI (3 + 21)/54 = 44.4%, ACT (0 + 4)/54 = 7.4%: +37 points; against DP only lift-cube 8:
    # 21/27 = 77.8% against 9/27 = 33.3%: +44 points.
    assert len(lines) == 2
    assert "ACT, over the 2 cells" in lines[0] and "(lift-cube 2, lift-cube 8)" in lines[0]
    assert "R&D-AI 24/54" in lines[0] and "ACT 4/54" in lines[0] and "+37 points" in lines[0]
    assert "Diffusion Policy, over the 1 cell with" in lines[1] and "9/27" in lines[1] and "+44 points" in lines[1]
    # Cells of two results folders add up: a MetaWorld cell of 25 episodes, R&D-AI 12, ACT 5. By hand: R&D-AI
    # (24 + 12)/79 = 45.6%, ACT (4 + 5)/79 = 11.4%: +34 points.
    mw_runs = tmp_path / w.MW_SPATIAL_FOLDER / "runs"
    mw_runs.mkdir(parents=True)
    run("rnd_ai__button-press-topdown-v3__n2", 12, n=25, folder=mw_runs)
    run("act__button-press-topdown-v3__n2", 5, n=25, folder=mw_runs)
    lines = w.few_demo_gap(cells + [(w.MW_SPATIAL_FOLDER, "button-press-topdown-v3", 2)])
    assert "(lift-cube 2, lift-cube 8, button-press-topdown-v3 2)" in lines[0]
    assert "R&D-AI 36/79" in lines[0] and "ACT 9/79" in lines[0] and "+34 points" in lines[0]


def test_panda_training_length_section_pairs_each_methods_3000_and_6000_step_runs(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)

    def run(folder, name, k, curve, status="done"):
        runs = tmp_path / folder / "runs"
        runs.mkdir(parents=True, exist_ok=True)
        chunk = {"0:27": {"successes": [True] * k + [False] * (27 - k)}}
        (runs / f"{name}__lift-cube__n8__seed0.json").write_text(
            json.dumps({"status": status, "eval_chunks": chunk, "loss_curve": curve}))

    run(w.PANDA_SPATIAL_FOLDER, "rnd_ai", 21, [[2950, 0.2], [3000, 0.19]])
    run(w.PANDA_SPATIAL_FOLDER, "act", 4, [[3000, 0.13]])
    assert w.panda_training_length_section() == []  # no 6,000-step run finished: no section
    run(w.PANDA_LONG_FOLDER, "act", 9, [[3000, 0.125], [3050, 0.12], [6000, 0.07]])
    run(w.PANDA_LONG_FOLDER, "rnd_ai", 0, [[3000, 0.18]], status="training")  # unfinished: not shown as done
    text = "\n".join(w.panda_training_length_section())
    assert "| ACT | 4/27 (6-32%) | 9/27 (19-52%) | 0.130 / 0.125 / 0.070 |" in text  # Wilson 95% for 9/27: 18.6-51.9%
    assert "| R&D-AI | 21/27 (59-89%) | not run yet | 0.190 / 0.180 / – |" in text


def test_panda_pair_section_tables_each_task_and_says_whether_rnd_doubles_act_on_both(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)
    runs = tmp_path / w.PANDA_PAIR_FOLDER / "runs"
    runs.mkdir(parents=True)

    def run(method, red, blue, status="done", loss=0.1):
        # Two lerobot-eval chunks of a --multitask run: each holds both tasks' successes.
        chunks = {f"{i}:{i + 25}": {"successes": {"lift-red-cube": [True] * r + [False] * (25 - r),
                                                  "lift-blue-cube": [True] * b + [False] * (25 - b)}}
                  for i, r, b in ((0, red[0], blue[0]), (25, red[1], blue[1]))}  # fmt: skip
        (runs / f"{method}__lift-red-cube+lift-blue-cube__n10__seed0.json").write_text(
            json.dumps({"status": status, "eval_chunks": chunks, "loss_curve": [[3000, loss]]}))

    assert w.panda_pair_section() == []  # nothing finished: no section
    run("rnd_ai", (20, 10), (12, 12), loss=0.0654)
    run("act", (0, 0), (0, 0), status="training")
    text = "\n".join(w.panda_pair_section())
    # Wilson 95% by hand: 30/50 46.2-72.4%, 24/50 34.8-61.5%, 54/100 44.3-63.4%.
    assert "| R&D-AI | 30/50 (46-72%) | 24/50 (35-61%) | 54/100 (44-63%) | 0.065 |" in text
    assert "| ACT | not run yet | not run yet | – | – |" in text and "separates" not in text
    run("act", (10, 10), (3, 2))  # 20/50 (28-54%) and 5/50 (4-21%): R&D-AI's 60% is less than twice 40%
    text = "\n".join(w.panda_pair_section())
    assert "| ACT | 20/50 (28-54%) | 5/50 (4-21%) | 25/100 (18-34%) | 0.100 |" in text
    assert "does not meet" in text and "it does on `lift-blue-cube`." in text
    run("act", (10, 5), (3, 2))  # red 15/50: 60% is exactly twice 30%, which counts
    text = "\n".join(w.panda_pair_section())
    assert "R&D-AI separates the tasks" in text and "overlap" not in text  # 30/50 (46-72%) against 15/50 (19-44%)
    run("rnd_ai", (1, 0), (0, 0))
    run("act", (0, 0), (0, 0))  # 1/50 (0.4-10.5%) against 0/50 (0-7.1%): twice, literally, within the intervals
    text = "\n".join(w.panda_pair_section())
    assert "it does on `lift-red-cube`." in text
    assert "On `lift-red-cube` (1/50 against 0/50) the two Wilson intervals overlap" in text
    run("rnd_ai", (0, 0), (0, 0))
    run("act", (0, 0), (0, 0))  # both fail everywhere: nothing is separated
    assert "it does on neither task." in "\n".join(w.panda_pair_section())
    single = tmp_path / w.PANDA_PAIR_SINGLE_FOLDER / "runs"
    single.mkdir(parents=True)
    (single / "rnd_ai__lift-red-cube__n10__seed0.json").write_text(json.dumps(
        {"status": "done", "eval_chunks": {"0:50": {"successes": [True] * 8 + [False] * 42}},
         "loss_curve": [[3000, 0.0712]]}))  # fmt: skip
    text = "\n".join(w.panda_pair_section())  # Wilson 95% for 8/50: 8.3-28.5%
    assert "| R&D-AI trained on `lift-red-cube` alone (" in text and ") | 8/50 (8-29%) | – | – | 0.071 |" in text
    assert "trained on `lift-blue-cube` alone" not in text  # not run: no row


def test_so101_calibration_rows_compare_measured_and_exact_cameras_per_task(tmp_path, monkeypatch):
    import json

    import benchmarks.write_benchmarks_md as w

    monkeypatch.setattr(w, "RESULTS", tmp_path)

    def run(folder, task, k, n=50):
        runs = tmp_path / folder / "runs"
        runs.mkdir(parents=True, exist_ok=True)
        chunk = {"0:50": {"successes": [True] * k + [False] * (n - k)}}
        (runs / f"rnd_ai__{task}__n10__seed0.json").write_text(json.dumps({"status": "done", "eval_chunks": chunk}))

    run(w.SO101_FOLDER, "reach-target", 3)
    run(w.SO101_FOLDER, "pick-cube", 0)
    assert w.so101_calibration_rows() == []  # no exact-calibration run: nothing to compare
    run(w.SO101_EXACT_FOLDER, "reach-target", 8)
    text = "\n".join(w.so101_calibration_rows())
    # Wilson 95% by hand: 3/50 2.1-16.2%, 0/50 0-7.1%, 8/50 8.3-28.5%; 3/50 - 8/50 = -10 points.
    assert "| measured by `lerobot-rnd-calibrate` | 3/50 (2-16%) | 0/50 (0-7%) |" in text
    assert "| MuJoCo's exact | 8/50 (8-29%) | not run yet |" in text
    assert "Measured against exact: reach-target -10 points." in text


def test_pair_open_loop_line_reads_frame_zero_of_an_other_task_run():
    import benchmarks.write_benchmarks_md as w

    assert w.pair_open_loop_line(None) == []
    names = ["dx", "dy", "dz", "drx", "dry", "drz", "gripper"]
    plain = {"joint_names": names, "draws": 4, "rows": [{"start_frame": 0, "episodes": 20, "slope": [0.5] * 7}]}
    assert w.pair_open_loop_line(plain) == []  # a run without --other-task says nothing about the task string
    row = {"start_frame": 0, "episodes": 20, "slope": [0.87, None, -0.061, 0, 0, 0.3, None],
           "task_effect": [0.0053, 0.0069, 0.0225, 0, 0, 0.04, 0], "draw_std": [0.224, 0.186, 0.19, 0, 0, 1.1, 0]}
    text = w.pair_open_loop_line({**plain, "rows": [{**row, "start_frame": 8}, row]})[1]
    assert "its 20 demos" in text and "slopes x 0.87, y –, z -0.06 (1:" in text
    assert "it moves by x 0.01, y 0.01, z 0.02 (mean" in text and "over 4 draws of x 0.22, y 0.19, z 0.19." in text
