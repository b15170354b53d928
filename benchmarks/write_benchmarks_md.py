#!/usr/bin/env python
"""Write docs/BENCHMARKS.md's current results and benchmarks/results/archive/ARCHIVE.md from the committed JSON.

The block of docs/BENCHMARKS.md between `<!-- cpu-results:start -->` and `<!-- cpu-results:end -->` is rebuilt
from the *current* results (benchmarks/results/INDEX.md says which those are; benchmarks/write_results_index.py
holds the statuses):

  one_step_sampling_test.json              benchmarks/sampler_steps.py: the shipped CPU tier (1 denoising step)
                                           on the CPU benchmark's R&D-AI checkpoints, test seeds
  cpu_3000_drawer/, cpu_3000_button/,      benchmarks/run_benchmark.py --scale cpu --steps 3000: ACT and Diffusion
  cpu_3000/, cpu_3000_reach_seeds/,        Policy (and the R&D-AI runs, sampled with 4 steps), 10 and 20 demos
  cpu_3000_reach_n20/, cpu_6000_reach_n20/
  reach_n20_6000steps_test.json            R&D-AI, 20 demos, 6,000 steps, 1 denoising step
  train_step_cpu*.json                     benchmarks/bench_train_step.py (one per CPU kind)
  inference_cpu_tier_avx512.json           benchmarks/bench_inference.py --configs cpu
  quickstart_drawer_cpu.json               examples/quickstart.sh's summary.json

and benchmarks/results/archive/ARCHIVE.md is rebuilt from the archived JSON that have no results.md of their own
(ablations, validation curves, traces' sources, earlier quickstarts and inference timings). Nothing in either
is typed by hand.

    python benchmarks/write_benchmarks_md.py
"""

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
RESULTS = REPO / "benchmarks" / "results"
ARCHIVE = RESULTS / "archive"
DOC = REPO / "docs" / "BENCHMARKS.md"
ARCHIVE_DOC = ARCHIVE / "ARCHIVE.md"
START, END = "<!-- cpu-results:start -->", "<!-- cpu-results:end -->"

# The last version of the code with the config switches retired from RnDConfig (their ablation rows are archived).
TAG = "ablation-switches-2026-12"
TAG_COMMIT = "b8b7dad"  # the commit the tag points to

METHODS = (("rnd_ai", "R&D-AI (`rnd_ai_cpu.json`)"), ("act", "ACT (`act_cpu.json`)"),
           ("diffusion", "Diffusion Policy (`diffusion_cpu.json`)"))  # fmt: skip
# The headline tasks and the run_benchmark.py folder whose ACT / Diffusion Policy runs they use (10 demos, seed 0).
HEADLINE = (("drawer-close-v3", "cpu_3000_drawer"), ("button-press-topdown-v3", "cpu_3000_button"),
            ("reach-v3", "cpu_3000"))  # fmt: skip
# The current run_benchmark.py folders. Their R&D-AI runs were trained and evaluated before the CPU tier moved to
# one denoising step (commit d916658), so they were sampled with 4; one_step_sampling_test.json re-evaluates
# those checkpoints with 1.
CURRENT_FOLDERS = ("cpu_3000_drawer", "cpu_3000_button", "cpu_3000", "cpu_3000_reach_seeds", "cpu_3000_reach_n20",
                   "cpu_6000_reach_n20")  # fmt: skip
FOUR_STEP_FOLDERS = ("cpu_3000_drawer", "cpu_3000_button", "cpu_3000", "cpu_3000_reach_seeds", "cpu_3000_reach_n20")
# Runs of a current folder that measure a superseded config: (folder, method, task) -> what they measured.
SUPERSEDED_RUNS = {("cpu_3000", "rnd_ai", "reach-v3"): "the earlier linear patch embedding"}


def _load(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


def wilson(successes: int, n: int) -> tuple[float, float]:
    """Wilson score 95% interval of a success rate (the harness's); (0, 1) when nothing was evaluated."""
    from benchmarks.harness.reports import wilson_interval

    return wilson_interval(successes, n) if n > 0 else (0.0, 1.0)


def cell(successes: int, n: int, bold: bool = False) -> str:
    """`k/n (lo-hi%)`, the interval a Wilson 95% one."""
    lo, hi = wilson(successes, n)
    text = f"{successes}/{n}"
    return f"{'**' + text + '**' if bold else text} ({100 * lo:.0f}-{100 * hi:.0f}%)"


def folder_run(folder: str, method: str, task: str, demos: int = 10, seed: int = 0) -> dict | None:
    """One run of a run_benchmark.py results folder (its entry in results.json), or None."""
    res = _load(RESULTS / folder / "results.json") or {"runs": []}
    return next((r for r in res["runs"] if r["method"] == method and r["task"] == task and r["demos"] == demos
                 and r.get("seed", 0) == seed and r.get("eval_episodes")), None)  # fmt: skip


def sampled_entry(res: dict, task: str, steps: int) -> dict | None:
    """The sampler_steps.py entry of one task at one number of denoising steps."""
    return next((e for e in res["entries"] if e["task"] == task and e["num_inference_steps"] == steps), None)


def headline_section(one_step: dict) -> list[str]:
    """Success per task of the shipped CPU configs: R&D-AI with 1 step, ACT and DP from the same benchmark runs."""
    heads = [f"`{task}`" for task, _ in HEADLINE]
    lines = [
        "### Success on MetaWorld (10 demos, 3,000 training steps, 50 test episodes per cell)",
        "",
        "Successes on evaluation seeds 1000-1049 with Wilson 95% intervals; the same demos and seeds for every "
        "method, batch 8, one training seed per cell. R&D-AI is the shipped CPU tier sampled with its one denoising "
        "step ([`one_step_sampling_test.json`](../benchmarks/results/one_step_sampling_test.json), which re-evaluates "
        "the benchmark's R&D-AI checkpoints); ACT and Diffusion Policy are the runs of "
        + ", ".join(f"[`{f}`](../benchmarks/results/{f}/results.md)" for _, f in HEADLINE) + ".",
        "",
        "| method | params | " + " | ".join(heads) + " | all three |",
        "| --- | ---: |" + " ---: |" * (len(HEADLINE) + 1),
    ]
    rows = {}
    for method, label in METHODS:
        cells, params = [], None
        for task, folder in HEADLINE:
            if method == "rnd_ai":
                e = sampled_entry(one_step, task, 1)
                run = _load(RESULTS / e["source"].removeprefix("benchmarks/results/")) if e else None
                cells.append((e["successes"], e["episodes"]) if e else None)
                params = params or (run or {}).get("n_params")
            else:
                r = folder_run(folder, method, task)
                cells.append((r["successes"], r["eval_episodes"]) if r else None)
                params = params or (r or {}).get("n_params")
        rows[method] = (label, params, cells)
    best = [max((c[i][0] for _, _, c in rows.values() if c[i]), default=None) for i in range(len(HEADLINE))]
    for method, (label, params, cells) in rows.items():
        text = [cell(*c, bold=c[0] == best[i]) if c else "not run" for i, c in enumerate(cells)]
        done = [c for c in cells if c]
        total = cell(sum(c[0] for c in done), sum(c[1] for c in done)) if len(done) == len(cells) else "–"
        lines.append(f"| {label} | {params / 1e6:.1f}M | " + " | ".join(text) + f" | {total} |" if params else
                     f"| {label} | – | " + " | ".join(text) + f" | {total} |")  # fmt: skip
    reach = sampled_entry(one_step, "reach-v3", 1)
    if reach:
        seed = reach["name"].rsplit("seed", 1)[-1]
        act0, act1 = folder_run("cpu_3000", "act", "reach-v3"), folder_run("cpu_3000_reach_seeds", "act", "reach-v3", seed=1)
        rnd0 = folder_run("cpu_3000_reach_seeds", "rnd_ai", "reach-v3")
        rnd1 = folder_run("cpu_3000_reach_seeds", "rnd_ai", "reach-v3", seed=1)
        line = (f"R&D-AI's reach-v3 checkpoint is training seed {seed} (ACT's and Diffusion Policy's are seed 0). "
                "Bold: the most successes in the column.")
        if act0 and act1 and rnd0 and rnd1:
            line += (f" Over two training seeds on reach-v3 ([`cpu_3000_reach_seeds`](../benchmarks/results/"
                     f"cpu_3000_reach_seeds/results.md), R&D-AI sampled with 4 steps there): R&D-AI "
                     f"{cell(rnd0['successes'] + rnd1['successes'], rnd0['eval_episodes'] + rnd1['eval_episodes'])}, "
                     f"ACT {cell(act0['successes'] + act1['successes'], act0['eval_episodes'] + act1['eval_episodes'])}.")
        lines += ["", line]
    return lines


def reach_n20_section(n20_6000: dict | None) -> list[str]:
    """reach-v3 with 20 demos: 3,000 steps for every method, 6,000 for R&D-AI and ACT."""
    lines = [
        "### reach-v3 with 20 demos",
        "",
        "The 10-demo set extended to 20 (the first 10 are the same demos), the same test seeds 1000-1049: "
        "[`cpu_3000_reach_n20`](../benchmarks/results/cpu_3000_reach_n20/results.md) (3,000 steps), "
        "[`cpu_6000_reach_n20`](../benchmarks/results/cpu_6000_reach_n20/results.md) (ACT, 6,000 steps) and "
        "[`reach_n20_6000steps_test.json`](../benchmarks/results/reach_n20_6000steps_test.json) (R&D-AI, 6,000 steps, "
        "one denoising step).",
        "",
        "| method | 3,000 steps | 6,000 steps |",
        "| --- | ---: | ---: |",
    ]
    long = {}
    if n20_6000:
        e = sampled_entry(n20_6000, "reach-v3", 1)
        long["rnd_ai"] = (e["successes"], e["episodes"]) if e else None
    r = folder_run("cpu_6000_reach_n20", "act", "reach-v3", demos=20)
    long["act"] = (r["successes"], r["eval_episodes"]) if r else None
    for method, label in METHODS:
        r = folder_run("cpu_3000_reach_n20", method, "reach-v3", demos=20)
        short = cell(r["successes"], r["eval_episodes"]) + (" (4 steps)" if method == "rnd_ai" else "") if r else "not run"
        lines.append(f"| {label} | {short} | {cell(*long[method]) if long.get(method) else 'not run'} |")
    if long.get("rnd_ai") and long.get("act"):
        (k_r, n_r), (k_a, n_a) = long["rnd_ai"], long["act"]
        lines += ["", f"**Here R&D-AI loses**: trained 6,000 steps on 20 demos, ACT succeeds on {k_a}/{n_a} and "
                      f"R&D-AI on {k_r}/{n_r}. [docs/REACH.md](REACH.md) has the investigation."]  # fmt: skip
    return lines


def cost_section(train_steps: list[tuple[str, dict]], inference: tuple[str, dict] | None) -> list[str]:
    """Training step and inference chunk per method, each as a ratio to ACT measured in the same run."""
    lines = [
        "### Cost: a training step and an action chunk, as ratios to ACT in the same run",
        "",
        "Medians on 2 CPU cores. A training step is batch 8 with data loading in the main process "
        "(`benchmarks/bench_train_step.py`); a chunk is one `predict_action_chunk` call at batch 1 "
        "(`benchmarks/bench_inference.py --configs cpu`). Absolute times move with the machine's load between runs; "
        "the ratios are measured in one run each.",
        "",
        "| measurement | JSON | R&D-AI | ACT | Diffusion Policy |",
        "| --- | --- | ---: | ---: | ---: |",
    ]
    for name, res in train_steps:
        by = {r["method"]: r for r in res["results"]}
        act = by.get("act_cpu")
        isa = res["machine"].get("cpu_capability", "")
        cells = []
        for method in ("rnd_ai_cpu", "act_cpu", "diffusion_cpu"):
            r = by.get(method)
            cells.append(f"{r['median_total_s']:.2f} s ({r['median_total_s'] / act['median_total_s']:.2f}x)"
                         if r and act else "–")  # fmt: skip
        lines.append(f"| training step, {isa} | [`{name}`](../benchmarks/results/{name}) | " + " | ".join(cells) + " |")
    dp_note = ""
    if inference:
        name, res = inference
        by = {r["method"]: r for r in res["results"]}
        act = by.get("ACT")
        isa = res.get("machine", {}).get("cpu_capability", "")
        cells = [f"{by[m]['median_ms']:.0f} ms ({by[m]['median_ms'] / act['median_ms']:.1f}x)" if m in by and act else "–"
                 for m in ("R&D-AI", "ACT", "Diffusion Policy")]  # fmt: skip
        lines.append(f"| one action chunk, {isa} | [`{name}`](../benchmarks/results/{name}) | " + " | ".join(cells) + " |")
        if "Diffusion Policy" in by:
            dp = by["Diffusion Policy"]
            dp_note = (f" The inference benchmark times Diffusion Policy at LeRobot's default size ({dp['config']}; "
                       f"{dp['params'] / 1e6:.1f}M parameters), not `diffusion_cpu.json`'s.")
        rnd = next((b for b in res.get("rnd_breakdown") or [] if b.get("config") == "cpu"), None)
        if rnd:
            dp_note += (f" One R&D-AI chunk (a separate timed pass): rendering {rnd['render_ms']:.0f} ms, the network "
                        f"{rnd['network_ms']:.0f} ms, the SVD registration {rnd['svd_ms']:.0f} ms.")
    lines += ["", "R&D-AI is `rnd_ai_cpu.json` (bf16 autocast where the CPU has native bf16, float32 on AVX2), "
                  "ACT `act_cpu.json`, Diffusion Policy `diffusion_cpu.json` in the training rows." + dp_note]
    for name, res in train_steps:
        lines += ["", f"<details><summary>Where a training step goes: {name}</summary>", "",
                  *train_step_section(res, name), "", "</details>"]
    return lines


def runs_section(one_step: dict | None, n20_6000: dict | None) -> list[str]:
    """Every current run: one line each, with its training length, sampling steps and JSON."""
    lines = [
        "### Every current run",
        "",
        "Each benchmark folder's `results.md` has its loss curves and plots, and each run JSON its exact "
        "`lerobot-train` / `lerobot-eval` commands. *Denoising steps* is what R&D-AI sampled with: the benchmark "
        "folders' R&D-AI runs predate the CPU tier's one-step default and used 4. Not listed, as superseded: "
        + "; ".join(f"`{f}`'s {m} run on {t} ({why})" for (f, m, t), why in SUPERSEDED_RUNS.items()) + ".",
        "",
        "| method | task | demos | training seed | steps | denoising steps | success | params | train loop | final loss | source |",
        "| --- | --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | --- |",
    ]
    labels = {"rnd_ai": "R&D-AI", "act": "ACT", "diffusion": "Diffusion Policy"}

    def row(method, task, demos, seed, steps, denoise, k, n, params, minutes, loss, link):
        return (f"| {labels.get(method, method)} | {task} | {demos} | {seed} | {steps} | {denoise} | {cell(k, n)} | "
                f"{f'{params / 1e6:.1f}M' if params else '–'} | {f'{minutes:.0f} min' if minutes else '–'} | "
                f"{f'{loss:.3f}' if loss is not None else '–'} | {link} |")

    for folder in CURRENT_FOLDERS:
        res = _load(RESULTS / folder / "results.json") or {"runs": []}
        link = f"[`{folder}`](../benchmarks/results/{folder}/results.md)"
        for r in res["runs"]:
            if r.get("collected_from") or not r.get("eval_episodes") or (folder, r["method"], r["task"]) in SUPERSEDED_RUNS:
                continue  # a run another folder holds is listed there
            rnd = r["method"].startswith("rnd")
            denoise = ("4" if folder in FOUR_STEP_FOLDERS else "1") if rnd else "–"
            curve = r.get("loss_curve") or []
            minutes = r["train_seconds"] / 60 if r.get("train_seconds") else None
            lines.append(row(r["method"], r["task"], r["demos"], r.get("seed", 0), r.get("steps") or "–", denoise,
                             r["successes"], r["eval_episodes"], r.get("n_params"), minutes,
                             curve[-1][1] if curve else None, link))  # fmt: skip
    for name, res in (("one_step_sampling_test.json", one_step), ("reach_n20_6000steps_test.json", n20_6000)):
        for e in (res or {}).get("entries", []):
            if e["num_inference_steps"] != 1:
                continue
            run = _load(REPO / e["source"]) if e["source"].endswith(".json") else None
            if run:
                demos, seed, steps = run["demos"], run.get("seed", 0), run["loss_curve"][-1][0]
            else:  # a checkpoint given by path: .../checkpoints/<step>/pretrained_model of a run on n<demos> demos
                parts = Path(e["checkpoint"]).parts
                steps = int(parts[-2]) if parts[-2].isdigit() else "–"
                demos = 20 if "n20" in e["checkpoint"] else 10
                seed = 0
            lines.append(row("rnd_ai", e["task"], demos, seed, steps, e["num_inference_steps"], e["successes"],
                             e["episodes"], (run or {}).get("n_params"), None, None,
                             f"[`{name}`](../benchmarks/results/{name})"))  # fmt: skip
    return lines


def train_step_section(res: dict, name: str = "train_step_cpu.json") -> list[str]:
    phases = ("data", "pre", "render", "forward", "backward", "optim")
    upstream = any(r.get("median_data_upstream_s") is not None for r in res["results"])
    isa = res["machine"].get("cpu_capability")
    lines = [
        f"### Where a training step goes (CPU{', ' + isa if isa else ''})",
        "",
        f"`{res['command']}` ({res['steps']} timed steps after {res['warmup']} warm-up, batch {res['batch_size']}, "
        f"{res['threads']} torch threads, {res['machine']['cores']} cores, torch {res['machine']['torch']}"
        f"{', CPU capability ' + isa if isa else ''}; "
        f"JSON: [`benchmarks/results/{name}`](../benchmarks/results/{name})). Medians in "
        "seconds; `data` is one batch from LeRobot's dataset in the main process (lerobot-train moves it to "
        "worker processes, which share the same two cores); *x ref* is the speed-up of the whole step over "
        f"`{res['reference']}` measured in the same run."
        + (" *data, LeRobot's query* is the same batch size read with LeRobot 0.4.4's own frame query, which decodes "
           "every camera of every queried row; `data` uses the plugin's column-first query "
           "(`lerobot_rnd/dataset_query.py`)." if upstream else ""),
        "",
        "| config | params | " + " | ".join(phases) + " | total | model step (no data) | x ref |"
        + (" data, LeRobot's query |" if upstream else ""),
        "| --- | ---: |" + " ---: |" * (len(phases) + 3 + int(upstream)),
    ]
    ref = next(r for r in res["results"] if r["method"] == res["reference"])
    ref_model = ref["median_total_s"] - ref["median_s"]["data"]
    for r in res["results"]:
        m = r["median_s"]
        model = r["median_total_s"] - m["data"]
        lines.append(
            f"| `{r['method']}` | {r['parameters'] / 1e6:.1f}M | " + " | ".join(f"{m[p]:.3f}" for p in phases)
            + f" | {r['median_total_s']:.3f} | {model:.3f} ({ref_model / model:.1f}x) | {r['speedup_vs_reference']:.2f} |"
            + (f" {r['median_data_upstream_s']:.3f} |" if upstream else "")
        )
    return lines


# Columns of MetaWorld's placement vector (rand_vec) that hold the goal, for tasks whose goal moves.
GOAL_COLUMNS = {"reach-v3": slice(3, 6), "reach-wall-v3": slice(3, 6)}
DISTANCE_BINS_CM = (0, 4, 6, 8, 100)


def generalisation_section(res: dict, folder: str) -> list[str]:
    """Success per evaluation episode against how far its goal lies from the nearest demonstration's goal."""
    import numpy as np

    lines = []
    for task, cols in GOAL_COLUMNS.items():
        runs = [r for r in res["runs"] if r["task"] == task and r.get("per_episode_success")]
        if not runs:
            continue
        placements = np.asarray(res["eval_sets"][task]["placements"], dtype=float)[:, cols]
        table = [
            f"#### Where the goal lies: {task}, success by distance from the goal to the nearest demo goal "
            f"(`benchmarks/results/{folder}`)",
            "",
            "How far each evaluation episode's goal is from the closest of the demonstrations' goals (the success "
            "radius is 5 cm). A policy that only replays its nearest demonstration succeeds in the first bins.",
            "",
        ]
        bins = list(zip(DISTANCE_BINS_CM[:-1], DISTANCE_BINS_CM[1:]))
        heads = [f"{lo}-{hi} cm" if hi < 100 else f">= {lo} cm" for lo, hi in bins]
        table += ["| method | demos | " + " | ".join(heads) + " |", "| --- | ---: |" + " ---: |" * len(bins)]
        for r in runs:
            train = np.asarray(res["datasets"][task][str(r["demos"])]["placements"], dtype=float)[:, cols]
            near_cm = 100 * np.linalg.norm(placements[:, None] - train[None], axis=-1).min(1)
            succ = np.asarray(r["per_episode_success"], dtype=bool)
            near_cm = near_cm[: len(succ)]
            cells = []
            for lo, hi in bins:
                m = (near_cm >= lo) & (near_cm < hi)
                cells.append(f"{int(succ[m].sum())}/{int(m.sum())}")
            table.append(f"| {r['label']} | {r['demos']} | " + " | ".join(cells) + " |")
        lines += table + [""]
    return lines


def ablation_section(res: dict, name: str) -> list[str]:
    lines = [
        f"### Ablations and validation: `{name}` (reach-v3, validation seeds, not the evaluation seeds)",
        "",
        res.get("description", "") + f" JSON: [`{name}`](../benchmarks/results/{name}).",
        "",
        "| row | demos | demos' expert | frames after success | cameras | patch embedding | network precision | training switches | sampler switches | steps | "
        "final loss | success | 95% interval | episodes |",
        "| --- | ---: | --- | ---: | --- | --- | --- | --- | --- | ---: | ---: | ---: | --- | ---: |",
    ]
    for row in res["rows"]:  # rows written before "demos" was recorded all used 10 demos
        lo, hi = row["ci95"]
        switches = row.get("trained_switches", {})
        embed = switches.get("patch_embed", "–")
        if "patch_size" in switches:
            embed += f", {switches['patch_size']} px"
        bf16 = row.get("bf16_autocast_on_this_cpu")
        precision = "–" if bf16 is None else ("bf16 autocast" if bf16 else "float32")
        lines.append(
            f"| {row['name']} | {row.get('demos', 10)} | {row.get('demos_expert_reach_target', '–')} | "
            f"{row.get('demos_extra_steps', 10)} | "  # rows without it: the recorder's default, 10, all along
            f"{' + '.join(row.get('demos_cameras') or ['corner2', 'behindGripper'])} | {embed} | {precision} | `{row['train']}` | "
            f"`{row['sampler']}` | {row['steps']} | "
            f"{row['final_loss'] if row.get('final_loss') is not None else '–'} | {100 * row['success_rate']:.0f}% | "
            f"{100 * lo:.0f}–{100 * hi:.0f}% | {row['episodes']} |"
        )
    return lines


def train_placements_section(res: dict, rel: str) -> list[str]:
    lines = [
        "### Do the policies fit their own demos? (training placements)",
        "",
        f"`{res['command']}` ([`{Path(rel).name}`](../{rel})): each "
        "policy replays the placements of the demos it was trained on, one episode each. MetaWorld's reach reward "
        "is 10 inside the 5 cm success radius and 10 / (1 + (3 (d - 5 cm) / m)^2) at a distance d beyond it, m being "
        "the start-to-goal distance (23-33 cm here): 9.3 is about 7.5 cm, 9.9 about 6 cm from the goal. The "
        "*demonstrator* row replays the demos' own recorded actions: how close the expert itself came.",
        "",
        "| policy | task | checkpoint | success | 95% interval | max reward per episode |",
        "| --- | --- | --- | ---: | --- | --- |",
    ]
    for task, eps in (res.get("demos") or {}).items():
        final = " ".join(f"{100 * e['final_obj_to_target_m']:.1f}" for e in eps)
        rewards = " ".join(f"{e['max_reward']:.2f}" for e in eps)
        lines.append(
            f"| demonstrator (recorded actions) | {task} | – | – | – | {rewards}; "
            f"gripper-goal distance at the last frame (cm): {final} |"
        )
    for r in res["rows"]:
        lo, hi = r["ci95"]
        ckpt = "/".join(Path(r["checkpoint"]).parts[-2:-1])
        lines.append(
            f"| {r['method']} | {r['task']} | {ckpt} | {r['successes']}/{r['episodes']} | {100 * lo:.0f}–{100 * hi:.0f}% "
            f"| {' '.join(f'{x:.2f}' for x in r['max_rewards'])} |"
        )
    return lines


def hand_expert_section(res: dict, fit: dict | None) -> list[str]:
    lines = [
        "### reach-v3 on the earlier demos (MetaWorld's own reach policy; superseded)",
        "",
        res["description"] + " JSON: [`benchmarks/results/archive/cpu_reach_hand_expert/`](../benchmarks/results/archive/cpu_reach_hand_expert/).",
        "",
        "| method | task | success | 95% interval | episodes |",
        "| --- | --- | ---: | --- | ---: |",
    ]
    for r in res["runs"]:
        lo, hi = r["ci95"]
        lines.append(f"| {r['label']} | {r['task']} | {r['successes']}/{r['eval_episodes']} | "
                     f"{100 * lo:.0f}–{100 * hi:.0f}% | {r['eval_episodes']} |")  # fmt: skip
    if fit:
        lines += [""] + train_placements_section(fit, "benchmarks/results/archive/cpu_reach_hand_expert/train_placements.json")[2:]
    return lines


def quickstart_section(results: list[tuple[str, dict]]) -> list[str]:
    lines = ["### Quickstart", ""]
    for name, res in results:
        s = res["seconds"]
        command = res.get("command") or "bash examples/quickstart.sh"
        if "TASK=" not in command:  # recorded when the script's default task was this one
            command = f"TASK={res['task']} {command}"
        lines.append(
            f"- `{command}` ({res['demos']} demos of {res['task']}, {res['steps']} training "
            f"steps, {res['eval_episodes']} evaluation episodes): **{res['successes']}/{res['eval_episodes']} "
            f"successes ({100 * res['success_rate']:.0f}%)** in {s['total'] / 60:.1f} minutes (record {s['record']} s, "
            f"train {s['train']} s, evaluate {s['eval']} s) on {res['machine']['cpus']} CPU cores "
            f"([`{name}`](../benchmarks/results/{name})). {res.get('note', '')}".rstrip()
        )
    return lines


def inference_section(res: dict, name: str = "inference_cpu_tier.json") -> list[str]:
    rows = {f"{r['method']} ({r['config']}; {r['params'] / 1e6:.1f}M parameters)": r for r in res["results"]}
    act = next((r for r in res["results"] if r["method"] == "ACT"), None)
    cpu = res.get("machine", {}).get("cpu_capability")
    lines = [
        f"### One action chunk at inference (CPU{f', {cpu}' if cpu else ''})",
        "",
        f"`{res['command']}` (batch {res['args']['batch']}, median of {res['args']['repeats']} interleaved calls "
        f"after warm-up; JSON: [`benchmarks/results/{name}`](../benchmarks/results/{name})).{' ' + res['note'] if res.get('note') else ''}",
        "",
        "| method (config) | median per chunk | ratio to ACT |",
        "| --- | ---: | ---: |",
    ]
    for label, r in rows.items():
        ratio = f"{r['median_ms'] / act['median_ms']:.1f}x" if act else "–"
        lines.append(f"| {label} | {r['median_ms']:.0f} ms | {ratio} |")
    breakdowns = res.get("rnd_breakdown") or []
    if breakdowns:
        lines += ["", "Where one R&D chunk goes (a separate timed pass with timers around the calls):", "",
                  "| R&D config | render | network | SVD (registration) | other | total | calls per chunk (render / network / SVD) |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | --- |"]  # fmt: skip
        for b in breakdowns:
            c = b["calls_per_chunk"]
            lines.append(f"| {b['config']} | {b['render_ms']:.0f} ms | {b['network_ms']:.0f} ms | {b['svd_ms']:.0f} ms | "
                         f"{b['other_ms']:.0f} ms | {b['total_ms']:.0f} ms | {c['render']} / {c['network']} / {c['svd']} |")  # fmt: skip
    return lines


def validation_curve_section(res: dict, name: str) -> list[str]:
    """Success on validation seeds at each evaluated checkpoint of one training run, with its plot."""
    stem = name.removesuffix(".json")
    lines = [
        f"### Success against training step: `{name}` (validation seeds, not the evaluation seeds)",
        "",
        " then ".join(f"`{c}`" for c in res.get("commands", [res.get("command")]))
        + f": {res['title']}. {res['note'].capitalize()}. JSON: [`{name}`](../benchmarks/results/{name}).",
        "",
        "| step | success | 95% interval | episodes | training loss (logged nearest the step) |",
        "| ---: | ---: | --- | ---: | ---: |",
    ]
    for row in sorted(res["rows"], key=lambda r: r["step"]):
        lo, hi = row["ci95"]
        loss = row.get("training_loss_near_step")
        lines.append(
            f"| {row['step']} | {row['successes']}/{row['episodes']} ({100 * row['success_rate']:.0f}%) | "
            f"{100 * lo:.0f}–{100 * hi:.0f}% | {row['episodes']} | {'–' if loss is None else f'{loss:.3f}'} |"
        )
    if (RESULTS / f"{stem}.png").exists():
        lines += ["", f"![success against training step](images/{stem}.png)"]
    return lines


def sampler_steps_section(res: dict, name: str) -> list[str]:
    """The same checkpoints sampled with different numbers of denoising steps (benchmarks/sampler_steps.py)."""
    from benchmarks.sampler_steps import table

    entries = res["entries"]
    order = list(dict.fromkeys(e["num_inference_steps"] for e in entries))
    test = all(e["test_seeds"] for e in entries)
    seeds = "the benchmark's evaluation seeds" if test else "validation seeds"
    lines = [
        f"### Denoising steps at inference: `{name}` ({seeds})",
        "",
        f"`{res['command']}`. {res['what'][:1].upper() + res['what'][1:]}. *x time of first* is the evaluation time against "
        f"{order[0]} step(s) in the same call; *same episodes as first* counts episodes with the same outcome. "
        f"JSON: [`{name}`](../benchmarks/results/{name}).",
        "",
        table(entries, order),
    ]
    reproduced = [e for e in entries if e.get("committed_successes") is not None and e["num_inference_steps"] == order[0]]
    if reproduced:
        same = sum(e["per_episode_success"] == e["committed_successes"] for e in reproduced)
        lines += ["", f"At {order[0]} step(s), {same} of {len(reproduced)} checkpoints repeat their benchmark "
                      "run's committed per-episode outcomes exactly."]  # fmt: skip
    return lines


# Issue 35's comparison: the four MetaWorld tasks, one policy per task against one policy for all four.
MULTITASK_TASKS = ("drawer-close-v3", "button-press-topdown-v3", "reach-v3", "door-close-v3")
MULTITASK_FOLDER = "cpu_3000_multitask"
SINGLE_TASK_FOLDERS = {**dict(HEADLINE), "door-close-v3": "cpu_3000_door"}


def run_file_cells(folder: str, method: str, tasks: tuple[str, ...], demos: int = 10, seed: int = 0) -> dict:
    """{task: (successes, episodes)} of one finished run JSON of a results folder (`runs/`): a one-task run
    (`tasks` of length 1) or a --multitask run over `tasks`; {} when it is not there or not finished."""
    run = _load(RESULTS / folder / "runs" / f"{method}__{'+'.join(tasks)}__n{demos}__seed{seed}.json")
    if not run or run.get("status") != "done":
        return {}
    out = {t: [0, 0] for t in tasks}
    for chunk in run["eval_chunks"].values():
        per_task = chunk["successes"] if isinstance(chunk["successes"], dict) else {tasks[0]: chunk["successes"]}
        for t, succ in per_task.items():
            out[t][0] += sum(bool(x) for x in succ)
            out[t][1] += len(succ)
    return {t: tuple(v) for t, v in out.items()}


def final_loss(folder: str, method: str, tasks: tuple[str, ...], demos: int = 10, step: int | None = None) -> float | None:
    """The logged training loss of a run JSON at its last logged step, or at `step`; None when not logged."""
    run = _load(RESULTS / folder / "runs" / f"{method}__{'+'.join(tasks)}__n{demos}__seed0.json") or {}
    curve = run.get("loss_curve") or []
    if step is not None:
        curve = [point for point in curve if point[0] == step]
    return curve[-1][1] if curve else None


def multitask_section(one_step: dict | None) -> list[str]:
    """One policy for four MetaWorld tasks against one policy per task (R&D-AI and ACT, 10 demos of each task)."""
    single: dict[str, dict] = {"rnd_ai": {}, "act": {}}
    for task in MULTITASK_TASKS:
        e = sampled_entry(one_step, task, 1) if one_step and task != "door-close-v3" else None
        if e:  # the headline's 1-step re-evaluation of the benchmark's R&D-AI checkpoint
            single["rnd_ai"][task] = (e["successes"], e["episodes"])
        else:
            single["rnd_ai"].update(run_file_cells(SINGLE_TASK_FOLDERS[task], "rnd_ai", (task,)))
        single["act"].update(run_file_cells(SINGLE_TASK_FOLDERS[task], "act", (task,)))
    multi = {m: run_file_cells(MULTITASK_FOLDER, m, MULTITASK_TASKS) for m in ("rnd_ai", "act")}
    lines = [
        "### One policy for four tasks (issue 35; 10 demos of each task, 3,000 steps, 50 test episodes per task)",
        "",
        f"`python benchmarks/run_benchmark.py --scale cpu --multitask --steps 3000 --save-freq 500 --tasks "
        f"{','.join(MULTITASK_TASKS)} --methods rnd_ai,act --out benchmarks/results/{MULTITASK_FOLDER}` trains one "
        "policy per method on all four tasks (one dataset holding each task's 10 one-task demos, every frame with its "
        "task's description) and evaluates it on each task from seeds 1000-1049 "
        f"([`{MULTITASK_FOLDER}`](../benchmarks/results/{MULTITASK_FOLDER}/)). R&D-AI conditions on the task "
        "string (one learned token per task); ACT has no task input, which is the point of the comparison. The "
        "one-task rows are the runs above (R&D-AI sampled with 1 step; its reach-v3 checkpoint is training seed 1) "
        "and door-close-v3's ([`cpu_3000_door`](../benchmarks/results/cpu_3000_door/)). Every run: batch 8, "
        "3,000 steps, so a multi-task policy sees each task a quarter as often as a one-task policy.",
        "",
        "| method | training | " + " | ".join(f"`{t}`" for t in MULTITASK_TASKS) + " | mean over the four |",
        "| --- | --- |" + " ---: |" * (len(MULTITASK_TASKS) + 1),
    ]
    means = {}
    for method, label in (("rnd_ai", "R&D-AI"), ("act", "ACT")):
        for kind, cells in (("one policy per task", single[method]), ("one policy, four tasks", multi[method])):
            text = [cell(*cells[t]) if t in cells else "not run yet" for t in MULTITASK_TASKS]
            if all(t in cells for t in MULTITASK_TASKS):
                k, n = sum(cells[t][0] for t in MULTITASK_TASKS), sum(cells[t][1] for t in MULTITASK_TASKS)
                means[(method, kind)] = k / n
                text.append(cell(k, n))
            else:
                text.append("–")
            lines.append(f"| {label} | {kind} | " + " | ".join(text) + " |")
    rs, rm = means.get(("rnd_ai", "one policy per task")), means.get(("rnd_ai", "one policy, four tasks"))
    am = means.get(("act", "one policy, four tasks"))
    verdict = []
    if rs is not None and rm is not None:
        verdict.append(f"R&D-AI multi-task against its one-task runs: {100 * (rm - rs):+.0f} points of mean success "
                       "(issue 35 asks for no more than 10 points lost)")
    if rm is not None and am is not None:
        verdict.append(f"R&D-AI multi-task against ACT multi-task: {100 * (rm - am):+.0f} points (asked: +10 or more)")
    losses = [(label, final_loss(MULTITASK_FOLDER, m, MULTITASK_TASKS)) for m, label in (("rnd_ai", "R&D-AI"), ("act", "ACT"))]
    losses = [f"{label} {loss:.3f}" for label, loss in losses if loss is not None]
    if verdict:
        lines += ["", "; ".join(verdict) + "."]
    if rs is not None and rm is not None and rm < rs - 0.10:
        lines += ["", "**Here R&D-AI loses, against itself**: one policy for four tasks succeeds far less often than one "
                  "policy per task, most on the tasks whose one-task runs were best. Only one multi-task setting has "
                  "been run: 3,000 steps, the one-task runs' budget, in which each task gets a quarter of the samples "
                  "(7.5 passes over the four-task dataset against 26 over door-close-v3's alone). Next: the same "
                  "runs with 12,000 steps (the one-task runs' samples per task)"
                  + (", and ACT multi-task." if am is None else ".")]  # fmt: skip
    if losses:
        lines += ["", "Training loss at step 3,000 of the multi-task runs (each method's own loss; curves in "
                  f"[`{MULTITASK_FOLDER}/loss_curves.png`](../benchmarks/results/{MULTITASK_FOLDER}/loss_curves.png)): "
                  + ", ".join(losses) + "."]  # fmt: skip
    if not (RESULTS / "panda_multitask_pair").exists():  # "not run yet" stops being said once its results exist
        lines += ["", ("The Panda pair whose tasks share a scene, so that only the task string tells them apart, is built "
                       "but not run yet: `lift-red-cube` and `lift-blue-cube` show a red and a blue cube in every image, "
                       "and the task names the cube to lift. Its command: `python benchmarks/run_benchmark.py --suite "
                       "panda --scale cpu --multitask --tasks lift-red-cube,lift-blue-cube --demos 10 --methods rnd_ai,act "
                       "--steps 3000 --out benchmarks/results/panda_multitask_pair`.")]  # fmt: skip
    return lines


# Issue 35's Panda pair: one scene with a red and a blue cube; only the task string says which cube to lift.
PANDA_PAIR_TASKS = ("lift-red-cube", "lift-blue-cube")
PANDA_PAIR_FOLDER = "panda_multitask_pair"
PANDA_PAIR_SINGLE_FOLDER = "panda_pair_single"  # R&D-AI on one task of the pair at a time, 10 demos, 3,000 steps


def panda_pair_section() -> list[str]:
    """One policy for the Panda pair (R&D-AI conditioned on the task string, ACT without a task input): successes
    per task from the --multitask run JSON of PANDA_PAIR_FOLDER, and whether R&D-AI separates the tasks (at least
    twice ACT's success on each, issue 35's condition). [] until some method's run has finished."""
    cells = {m: run_file_cells(PANDA_PAIR_FOLDER, m, PANDA_PAIR_TASKS) for m in ("rnd_ai", "act")}
    if not any(cells.values()):
        return []
    lines = [
        "### The Panda pair whose tasks share a scene (issue 35; 10 demos of each task, 3,000 steps)",
        "",
        ("`lift-red-cube` and `lift-blue-cube` (`--env.type=rnd_panda`) show the same scene: a red and a blue 4 cm "
         "cube, each at a random position and yaw, at least 12 cm apart. The task string names the cube to lift, and "
         "lifting the other one fails, so only the task string tells the two tasks apart. `python "
         "benchmarks/run_benchmark.py --suite panda --scale cpu --multitask --tasks "
         f"{','.join(PANDA_PAIR_TASKS)} --demos 10 --methods rnd_ai,act --steps 3000 --out "
         f"benchmarks/results/{PANDA_PAIR_FOLDER}` records 10 random-placement demos of each task into one dataset, "
         "trains one policy per method on it and evaluates it on each task from seeds 1000-1049 "
         f"([`{PANDA_PAIR_FOLDER}`](../benchmarks/results/{PANDA_PAIR_FOLDER}/)). R&D-AI reads the task string (one "
         "learned token per task); ACT has no task input, so it cannot know which cube to lift."),
        "",
        "| method | " + " | ".join(f"`{t}`" for t in PANDA_PAIR_TASKS) + " | both | training loss at the end (each method's own) |",
        "| --- |" + " ---: |" * (len(PANDA_PAIR_TASKS) + 2),
    ]
    for method in ("rnd_ai", "act"):
        got = cells[method]
        text = [cell(*got[t]) if t in got else "not run yet" for t in PANDA_PAIR_TASKS]
        text.append(cell(sum(got[t][0] for t in got), sum(got[t][1] for t in got)) if got else "–")
        loss = final_loss(PANDA_PAIR_FOLDER, method, PANDA_PAIR_TASKS) if got else None
        text.append("–" if loss is None else f"{loss:.3f}")
        lines.append(f"| {TABLE_METHODS[method]} | " + " | ".join(text) + " |")
    for task in PANDA_PAIR_TASKS:  # the single-task controls: R&D-AI trained on one task of the pair alone
        alone = run_file_cells(PANDA_PAIR_SINGLE_FOLDER, "rnd_ai", (task,)).get(task)
        if alone:
            loss = final_loss(PANDA_PAIR_SINGLE_FOLDER, "rnd_ai", (task,))
            lines.append(f"| R&D-AI trained on `{task}` alone ([`{PANDA_PAIR_SINGLE_FOLDER}`](../benchmarks/results/"
                         f"{PANDA_PAIR_SINGLE_FOLDER}/)) | "
                         + " | ".join(cell(*alone) if t == task else "–" for t in PANDA_PAIR_TASKS)
                         + f" | – | {'–' if loss is None else f'{loss:.3f}'} |")  # fmt: skip
    rnd, act = cells["rnd_ai"], cells["act"]
    if rnd and act:
        # "At least twice ACT's success" on every task; a task both methods fail is not separated.
        separated = [t for t in PANDA_PAIR_TASKS
                     if rnd[t][0] > 0 and rnd[t][0] / rnd[t][1] >= 2 * act[t][0] / act[t][1]]  # fmt: skip
        verdict = ("R&D-AI separates the tasks: on each its success is at least twice ACT's (issue 35's condition)."
                   if len(separated) == len(PANDA_PAIR_TASKS) else
                   "R&D-AI does not meet issue 35's condition (at least twice ACT's success on each task): it does on "
                   + (", ".join(f"`{t}`" for t in separated) if separated else "neither task") + ".")  # fmt: skip
        # Twice ACT's rate can be 1 success against none: say when the two intervals overlap.
        overlap = [t for t in separated if wilson(*rnd[t])[0] <= wilson(*act[t])[1]]
        if overlap:
            verdict += (" On " + ", ".join(f"`{t}` ({rnd[t][0]}/{rnd[t][1]} against {act[t][0]}/{act[t][1]})"
                                           for t in overlap)
                        + " the two Wilson intervals overlap, so that is no evidence that the task string is read.")  # fmt: skip
        lines += ["", verdict]
    lines += pair_open_loop_line(_load(RESULTS / PANDA_PAIR_OPEN_LOOP))
    return lines


PANDA_PAIR_OPEN_LOOP = "chunk_goal_response_panda_pair_rnd_ai.json"


def pair_open_loop_line(res: dict | None) -> list[str]:
    """What the task string does to R&D-AI's first chunk on the pair's demos (benchmarks/chunk_goal_response.py
    --other-task, frame 0): slopes on the demos' motion and the change the task string makes against the spread
    over draws, per position axis. [] without that JSON."""
    row = next((r for r in (res or {}).get("rows", []) if r["start_frame"] == 0 and "task_effect" in r), None)
    if row is None:
        return []
    names = res.get("joint_names") or []
    axes = [i for i, n in enumerate(names) if n in ("dx", "dy", "dz")]

    def fmt(values):
        return ", ".join(f"{names[i][1:]} {'–' if values[i] is None else f'{values[i]:.2f}'}" for i in axes)

    return ["", (f"Open loop on its {row['episodes']} demos at their first frame ([`{PANDA_PAIR_OPEN_LOOP}`]"
                 f"(../benchmarks/results/{PANDA_PAIR_OPEN_LOOP}), `benchmarks/chunk_goal_response.py --other-task`), "
                 f"R&D-AI's first chunk follows the demos' motion with slopes {fmt(row['slope'])} (1: follows, 0: one "
                 "motion for every scene). Fed the other task's string with the same noise, it moves by "
                 f"{fmt([round(e, 3) for e in row['task_effect']])} (mean per episode) against a spread over "
                 f"{res['draws']} draws of {fmt(row['draw_std'])}.")]


TABLE_METHODS = {"rnd_ai": "R&D-AI", "act": "ACT", "diffusion": "Diffusion Policy"}


def method_by_run_table(folder: str, columns: list[tuple[str, int]], keep) -> list[str]:
    """A markdown table of one results folder's one-task runs: a row per method of TABLE_METHODS, a column per
    (task, demos) of `columns` for which `keep(task, demos, finished)` holds (`finished`: some method has a
    finished run there); "not run yet" where a method has none. [] when no column is kept."""
    found = {(m, t, n): run_file_cells(folder, m, (t,), demos=n).get(t) for m in TABLE_METHODS for t, n in columns}
    columns = [(t, n) for t, n in columns if keep(t, n, any(found[(m, t, n)] for m in TABLE_METHODS))]
    if not columns:
        return []
    rows = [f"| {name} | " + " | ".join(cell(*found[(m, t, n)]) if found[(m, t, n)] else "not run yet"
                                      for t, n in columns) + " |" for m, name in TABLE_METHODS.items()]  # fmt: skip
    return [
        "| method | " + " | ".join(f"{t}, {n} demos" for t, n in columns) + " |",
        "| --- | " + " | ".join("---" for _ in columns) + " |",
        *rows,
    ]


SO101_FOLDER = "so101_random"
SO101_TASKS = ("reach-target", "pick-cube")
SO101_DEMOS = (10, 20)
SO101_EXACT_FOLDER = "so101_exact_calibration"


def so101_section() -> list[str]:
    """The simulated SO-101's success table (issue 34): one row per method, one column per task and number of demos
    (10 always; 20 once a method has a finished run with 20), from the run JSON of SO101_FOLDER."""
    columns = [(t, n) for n in SO101_DEMOS for t in SO101_TASKS]
    table = method_by_run_table(SO101_FOLDER, columns, keep=lambda t, n, finished: n == SO101_DEMOS[0] or finished)
    return [
        "### Simulated SO-101 (joint-space arm, cameras measured by `lerobot-rnd-calibrate`)",
        "",
        "Random demos, 3,000 training steps, 50 test episodes from seed 1000 (Wilson 95% intervals); "
        f"[benchmarks/results/{SO101_FOLDER}](../benchmarks/results/{SO101_FOLDER}/results.md), "
        "`policies_config/so101/`. What the failures show: [docs/SO101.md](SO101.md). reach-target's ball stands on "
        "a post that shows where it is; the runs on the floating ball, which the front camera could not place, are "
        "archived (listed in [INDEX.md](../benchmarks/results/INDEX.md)).",
        "",
        *table,
        *so101_calibration_rows(),
    ]


def so101_calibration_rows() -> list[str]:
    """R&D-AI with the measured cameras (SO101_FOLDER) against MuJoCo's exact ones (SO101_EXACT_FOLDER, trained with
    `--calibration exact` on the same demos), 10 demos per task; [] until an exact-calibration run has finished."""
    demos = SO101_DEMOS[0]
    measured = {t: c for t in SO101_TASKS for c in [run_file_cells(SO101_FOLDER, "rnd_ai", (t,), demos).get(t)] if c}
    exact = {t: c for t in SO101_TASKS for c in [run_file_cells(SO101_EXACT_FOLDER, "rnd_ai", (t,), demos).get(t)] if c}
    if not exact:
        return []
    lines = ["", (f"R&D-AI trained on the same {demos} demos per task with MuJoCo's exact cameras instead "
                  f"(`--calibration exact`, [benchmarks/results/{SO101_EXACT_FOLDER}](../benchmarks/results/"
                  f"{SO101_EXACT_FOLDER}/)): issue 34 asks the measured cameras to come within 10 points of the exact "
                  "ones."),
             "", "| R&D-AI cameras | " + " | ".join(f"{t}, {demos} demos" for t in SO101_TASKS) + " |",
             "| --- |" + " ---: |" * len(SO101_TASKS)]  # fmt: skip
    for label, cells in (("measured by `lerobot-rnd-calibrate`", measured), ("MuJoCo's exact", exact)):
        lines.append(f"| {label} | " + " | ".join(cell(*cells[t]) if t in cells else "not run yet"
                                                  for t in SO101_TASKS) + " |")  # fmt: skip
    both = [t for t in SO101_TASKS if t in measured and t in exact]
    if both:
        gaps = [f"{t} {100 * (measured[t][0] / measured[t][1] - exact[t][0] / exact[t][1]):+.0f} points" for t in both]
        lines += ["", "Measured against exact: " + ", ".join(gaps) + "."]
    return lines


PANDA_SPATIAL_FOLDER = "panda_spatial"
PANDA_SPATIAL_TASKS = ("lift-cube", "slide-block", "push-block")
PANDA_SPATIAL_DEMOS = (2, 4, 8, 16)


def few_demo_gap(cells: list[tuple[str, str, int]], max_demos: int = 8) -> list[str]:
    """Issue 33's done condition, one line per baseline of TABLE_METHODS: R&D-AI's and the baseline's successes
    summed over the (results folder, task, demos) `cells` with at most `max_demos` demos that both have finished,
    and the difference of the two rates in points. [] when no baseline shares such a cell with R&D-AI."""
    lines = []
    few = [(folder, t, n) for folder, t, n in cells if n <= max_demos]
    for method, name in TABLE_METHODS.items():
        if method == "rnd_ai":
            continue
        pairs = [(run_file_cells(f, "rnd_ai", (t,), demos=n).get(t), run_file_cells(f, method, (t,), demos=n).get(t),
                  f"{t} {n}") for f, t, n in few]  # fmt: skip
        pairs = [p for p in pairs if p[0] and p[1]]
        if not pairs:
            continue
        (k_r, n_r), (k_b, n_b) = ([sum(p[i][j] for p in pairs) for j in (0, 1)] for i in (0, 1))
        gap = 100 * (k_r / n_r - k_b / n_b)
        count = f"{len(pairs)} cell{'s' * (len(pairs) != 1)}"
        lines.append(f"- Against {name}, over the {count} with {max_demos} demos or fewer that both have "
                     f"finished ({', '.join(p[2] for p in pairs)}): R&D-AI {cell(k_r, n_r)}, {name} "
                     f"{cell(k_b, n_b)}, a difference of {gap:+.0f} points (the issue asks for +15).")  # fmt: skip
    return lines


def curve_figures(folder: str) -> list[str]:
    """The harness's success-against-demos plot of a results folder (Wilson intervals) inline, and a link to its
    training-loss curves; [] when neither was written."""
    out = []
    if (RESULTS / folder / "success_vs_demos.png").exists():
        out += ["", f"![success against the number of demos, Wilson 95% intervals](../benchmarks/results/{folder}/"
                    + "success_vs_demos.png)"]
    if (RESULTS / folder / "loss_curves.png").exists():
        out += ["", f"Training losses of these runs: [loss_curves.png](../benchmarks/results/{folder}/loss_curves.png)."]
    return out


def panda_spatial_section() -> list[str]:
    """The Panda spatial-protocol table (issue 33): one row per method, one column per task and number of
    furthest-point demos that some method has finished, from the run JSON of PANDA_SPATIAL_FOLDER; then the
    harness's heat maps of that folder. Empty when no run has finished."""
    columns = [(t, n) for t in PANDA_SPATIAL_TASKS for n in PANDA_SPATIAL_DEMOS]
    table = method_by_run_table(PANDA_SPATIAL_FOLDER, columns, keep=lambda t, n, finished: finished)
    if not table:
        return []
    folder = RESULTS / PANDA_SPATIAL_FOLDER
    maps = [f"[{t}](../benchmarks/results/{PANDA_SPATIAL_FOLDER}/heatmap_{t}.png)" for t in PANDA_SPATIAL_TASKS
            if (folder / f"heatmap_{t}.png").exists()]  # fmt: skip
    return [
        "### Panda, spatial protocol (6-DoF gripper, furthest-point demos)",
        "",
        "Demos by furthest-point sampling over the object's (x, y, yaw) from the centre of its range (yaw modulo the "
        "object's 90-degree symmetry, except slide-block's); the front camera framed on the placement range (the cube 10-16 px wide at "
        "128 px) and a 60-degree wrist camera; the scripted expert approaches the object at 0.4 of full speed; "
        "evaluation on "
        "a 3 x 3 x 3 grid of cell centres over x, y and yaw (27 episodes per cell of the table, Wilson 95% "
        "intervals); 3,000 training steps at batch 8; `policies_config/panda/` (R&D-AI with 16-px patches, chosen "
        "on validation seeds 100-119); "
        f"[benchmarks/results/{PANDA_SPATIAL_FOLDER}](../benchmarks/results/{PANDA_SPATIAL_FOLDER}/"
        f"{'results.md' if (folder / 'results.md').exists() else 'runs/'})"
        + (f"; heat maps with the training placements marked: {', '.join(maps)}" if maps else "") + ". "
        "Push-block's and pick-place's target is drawn at random (seeded) for demos and test cells alike; "
        "slide-block's lies 10 cm along the block's own +y axis (RLBench's slide-block-to-target, the paper's spatial "
        "task), so the push direction and the gripper turn with the block's yaw. Five "
        "earlier rounds are archived: `panda_spatial_raw_yaw` (demos sampled without the yaw symmetry), "
        "`panda_spatial_camera_v1` (cameras that showed the cube 8-11 px wide), `panda_spatial_fast_expert` (an "
        "expert that made its whole approach within one action chunk), `panda_spatial_patch32` (R&D-AI with "
        "32-px patches, which did not read the cube's position) and `panda_spatial_push_centre_target` "
        "(push-block with the target at the centre of its range where valid: most demos pushed to the centre, "
        "most test cells did not).",
        "",
        *table,
        *curve_figures(PANDA_SPATIAL_FOLDER),
        *(["", "R&D-AI against each baseline over the cells with few demos (issue 33's done condition):", "",
            *gap] if (gap := few_demo_gap([(PANDA_SPATIAL_FOLDER, t, n) for t, n in columns])) else []),
    ]


MW_SPATIAL_FOLDER = "cpu_3000_button_spatial"
MW_SPATIAL_TASK = "button-press-topdown-v3"


def metaworld_spatial_section() -> list[str]:
    """MetaWorld's spatial protocol (issue 33: one MetaWorld task, 2, 4, 8, 16 furthest-point demos, R&D-AI and
    ACT): one row per method, one column per demo count that some method has finished, from MW_SPATIAL_FOLDER's run
    JSON; its heat map; R&D-AI against ACT over the cells with 8 demos or fewer. [] until a run has finished."""
    columns = [(MW_SPATIAL_TASK, n) for n in PANDA_SPATIAL_DEMOS]
    table = method_by_run_table(MW_SPATIAL_FOLDER, columns, keep=lambda t, n, finished: finished)
    if not table:
        return []
    folder = RESULTS / MW_SPATIAL_FOLDER
    heat = folder / f"heatmap_{MW_SPATIAL_TASK}.png"
    gap = few_demo_gap([(MW_SPATIAL_FOLDER, t, n) for t, n in columns])
    both = few_demo_gap([(PANDA_SPATIAL_FOLDER, t, n) for t in PANDA_SPATIAL_TASKS for n in PANDA_SPATIAL_DEMOS]
                        + [(MW_SPATIAL_FOLDER, t, n) for t, n in columns])  # fmt: skip
    return [
        f"### MetaWorld `{MW_SPATIAL_TASK}`, spatial protocol (furthest-point demos)",
        "",
        ("Demos by furthest-point sampling over the button's (x, y), the first at the placement nearest the range's "
         "mean; evaluation on a 5 x 5 grid over x and y, edges included (25 episodes per cell of the table, Wilson 95% "
         "intervals); 3,000 training steps at batch 8, the configs of `policies_config/metaworld/`; one call per "
         "method and demo count: `python benchmarks/run_benchmark.py --scale cpu --protocol spatial --tasks "
         f"{MW_SPATIAL_TASK} --demos N --methods M --steps 3000 --resume --out benchmarks/results/{MW_SPATIAL_FOLDER}` "
         f"([`{MW_SPATIAL_FOLDER}`](../benchmarks/results/{MW_SPATIAL_FOLDER}/"
         f"{'results.md' if (folder / 'results.md').exists() else 'runs/'}))."),
        "",
        *table,
        *curve_figures(MW_SPATIAL_FOLDER),
        *(["", f"![success per grid cell, training placements marked](../benchmarks/results/{MW_SPATIAL_FOLDER}/"
               + f"{heat.name})"] if heat.exists() else []),
        *(["", "R&D-AI against each baseline over the cells with few demos:", "", *gap] if gap else []),
        *(["", "Over the spatial protocol's cells of both suites (the Panda tasks above and this one):", "", *both]
          if gap else []),
    ]


PANDA_RANDOM_FOLDER = "panda_random"
PANDA_RANDOM_TASKS = ("pick-place", "press-button")
PANDA_RANDOM_FIT = "train_placements_panda_press_n10.json"  # the press-button checkpoints on their own demos


def panda_random_section() -> list[str]:
    """The Panda suite's random protocol (issue 33: pick-place and press-button, 10 random demos): one row per method,
    one column per task with a finished run, from the run JSON of PANDA_RANDOM_FOLDER. [] until a run has finished."""
    columns = [(t, 10) for t in PANDA_RANDOM_TASKS]
    table = method_by_run_table(PANDA_RANDOM_FOLDER, columns, keep=lambda t, n, finished: finished)
    if not table:
        return []
    return [
        "### Panda, random protocol (6-DoF gripper, 10 random demos)",
        "",
        ("Demos at uniformly drawn placements (object x, y and yaw; pick-place's target too), the recording seed 0; "
         "50 test episodes from seed 1000 (Wilson 95% intervals); 3,000 training steps at batch 8, the configs of "
         "`policies_config/panda/`; `python benchmarks/run_benchmark.py --suite panda --scale cpu --tasks "
         f"{','.join(PANDA_RANDOM_TASKS)} --demos 10 --steps 3000 --out benchmarks/results/{PANDA_RANDOM_FOLDER}` "
         f"([`{PANDA_RANDOM_FOLDER}`](../benchmarks/results/{PANDA_RANDOM_FOLDER}/results.md))."),
        "",
        *table,
        *panda_random_fit_lines(_load(RESULTS / PANDA_RANDOM_FIT)),
    ]


def panda_random_fit_lines(res: dict | None) -> list[str]:
    """One line per checkpoint of an eval_train_placements.py JSON: its successes on its own demo placements."""
    if not res:
        return []
    fits = ", ".join(f"{TABLE_METHODS.get(r['method'], r['method'])} {r['task']} {r['successes']}/{r['episodes']}"
                     for r in res["rows"])  # fmt: skip
    return ["", (f"On their own demo placements ([`{PANDA_RANDOM_FIT}`](../benchmarks/results/{PANDA_RANDOM_FIT}), "
                 f"one episode each): {fits}.")]  # fmt: skip


PANDA_LONG_FOLDER = "panda_spatial_6000"


def panda_training_length_section() -> list[str]:
    """lift-cube with 8 furthest-point demos, R&D-AI and ACT trained 3,000 steps (PANDA_SPATIAL_FOLDER) and 6,000
    steps (PANDA_LONG_FOLDER) on the same demos and test cells: successes and training losses. [] until a 6,000-step
    run has finished."""
    task, demos = ("lift-cube",), 8
    rows = []
    for method in ("rnd_ai", "act"):
        short = run_file_cells(PANDA_SPATIAL_FOLDER, method, task, demos=demos).get(task[0])
        long = run_file_cells(PANDA_LONG_FOLDER, method, task, demos=demos).get(task[0])
        losses = [final_loss(PANDA_SPATIAL_FOLDER, method, task, demos),
                  final_loss(PANDA_LONG_FOLDER, method, task, demos, step=3000),
                  final_loss(PANDA_LONG_FOLDER, method, task, demos) if long else None]  # fmt: skip
        loss_text = " / ".join("–" if v is None else f"{v:.3f}" for v in losses)
        rows.append((method, short, long, loss_text))
    if not any(long for _, _, long, _ in rows):
        return []
    lines = [
        "#### lift-cube with 8 demos: 3,000 against 6,000 training steps",
        "",
        ("ACT's loss was still falling at 3,000 steps, so R&D-AI and ACT were trained again for 6,000 steps on the same "
         "8 demos and evaluated on the same 27 cells: `python benchmarks/run_benchmark.py --suite panda --scale cpu "
         "--protocol spatial --tasks lift-cube --demos 8 --methods act,rnd_ai --steps 6000 --out "
         f"benchmarks/results/{PANDA_LONG_FOLDER}` ([`{PANDA_LONG_FOLDER}`](../benchmarks/results/{PANDA_LONG_FOLDER}/)). "
         "R&D-AI's learning rate follows a cosine over the run's steps, so its 6,000-step run is a new run, not the "
         "3,000-step one continued; ACT's is constant."),
        "",
        "| method | 3,000 steps | 6,000 steps | training loss: 3,000-step run at its end / 6,000-step run at 3,000 / at 6,000 |",
        "| --- | ---: | ---: | ---: |",
    ]
    for method, short, long, loss_text in rows:
        lines.append(f"| {TABLE_METHODS[method]} | {cell(*short) if short else 'not run'} | "
                     f"{cell(*long) if long else 'not run yet'} | {loss_text} |")  # fmt: skip
    return lines


def current_block() -> list[str]:
    """The generated opening of docs/BENCHMARKS.md: the current results of the shipped configs."""
    one_step = _load(RESULTS / "one_step_sampling_test.json")
    n20_6000 = _load(RESULTS / "reach_n20_6000steps_test.json")
    parts = [START, "", "## Current results (generated by `benchmarks/write_benchmarks_md.py` from the JSON)", "",
             "The shipped CPU configs of `policies_config/metaworld/`: `rnd_ai_cpu.json` (R&D-AI, 6.0M parameters, "
             "one denoising step and the final action step), `act_cpu.json` and `diffusion_cpu.json`. Every figure "
             "below comes from a JSON that [benchmarks/results/INDEX.md](../benchmarks/results/INDEX.md) lists as "
             "current.", ""]  # fmt: skip
    if one_step:
        parts += headline_section(one_step) + [""]
    parts += reach_n20_section(n20_6000) + [""]
    if (RESULTS / MULTITASK_FOLDER).exists():
        parts += multitask_section(one_step) + [""]
    pair = panda_pair_section()
    parts += pair + [""] if pair else []
    if (RESULTS / SO101_FOLDER / "runs").exists():
        parts += so101_section() + [""]
    panda = panda_spatial_section()
    if panda:
        parts += panda + [""]
        longer = panda_training_length_section()
        parts += longer + [""] if longer else []
    mw_spatial = metaworld_spatial_section()
    parts += mw_spatial + [""] if mw_spatial else []
    random_protocol = panda_random_section()
    parts += random_protocol + [""] if random_protocol else []
    train_steps = [(p.name, _load(p)) for p in sorted(RESULTS.glob("train_step_cpu*.json"))]
    inference = RESULTS / "inference_cpu_tier_avx512.json"
    parts += cost_section(train_steps, (inference.name, _load(inference)) if inference.exists() else None) + [""]
    quick = [(p.name, _load(p)) for p in sorted(RESULTS.glob("quickstart*_cpu.json"))]
    if quick:
        parts += quickstart_section(quick) + [""]
    parts += runs_section(one_step, n20_6000) + [""]
    parts += [
        "## Archived results",
        "",
        "Superseded and exploratory results (the 1,000-step benchmark, the linear patch embedding, 4-step sampling "
        "where a 1-step re-evaluation exists, ablations on validation seeds, rollout traces, earlier quickstarts and "
        "timings) are kept under [`benchmarks/results/archive/`](../benchmarks/results/archive/): "
        "[INDEX.md](../benchmarks/results/INDEX.md) lists each with the command that produced it and one line of why "
        "it was superseded, and [ARCHIVE.md](../benchmarks/results/archive/ARCHIVE.md) shows their tables. The config "
        "switches retired from `RnDConfig` (`point_update` variants other than x0/ddim, `denoise_step`, "
        "`obs_encoder=resnet18`, `patch_embed=conv3x3`, `train_first_step_fraction`, `camera_dropout`, "
        "`image_shift_augment`, `use_ema`, `embedding_init_std`, per-horizon action normalisation, `render_history`, "
        f"the loss weights) were last in the code at git tag `{TAG}` (commit `{TAG_COMMIT}`); their ablation rows "
        "are in the archive.",
        "",
        END,
    ]
    return parts


# Links in the sections point from docs/ (`../benchmarks/results/...`, `images/...`); ARCHIVE.md lives in
# benchmarks/results/archive/.
_ARCHIVE_LINKS = (("](../benchmarks/results/archive/", "]("), ("](../benchmarks/results/", "](../"),
                  ("](images/archive/", "]("), ("](images/", "](../../../docs/images/"))  # fmt: skip


def archive_page() -> str:
    """benchmarks/results/archive/ARCHIVE.md: the tables of the archived JSON that have no results.md."""
    parts = ["# Archived results (generated by `benchmarks/write_benchmarks_md.py`; do not edit)", "",
             "Superseded or exploratory: [../INDEX.md](../INDEX.md) says why for each. Kept as measured; the "
             "commands in them name the paths before the move to `archive/`. Run folders (`cpu*/`, `smoke/`) have "
             "their own `results.md`.", ""]  # fmt: skip
    quick = [(f"archive/{p.name}", _load(p)) for p in sorted(ARCHIVE.glob("quickstart*_cpu.json"))]
    if quick:
        parts += ["### Earlier quickstarts"] + quickstart_section(quick)[1:] + [""]
    for path in sorted(ARCHIVE.glob("inference_cpu_tier*.json")):
        parts += inference_section(_load(path), f"archive/{path.name}") + [""]
    fit = _load(RESULTS / "cpu_3000" / "train_placements.json")
    if fit:  # the earlier linear-embedding R&D-AI of cpu_3000 on its own demos
        parts += train_placements_section(fit, "benchmarks/results/cpu_3000/train_placements.json") + [""]
    hand = _load(ARCHIVE / "cpu_reach_hand_expert" / "results_reach.json")
    if hand:
        parts += hand_expert_section(hand, _load(ARCHIVE / "cpu_reach_hand_expert" / "train_placements.json")) + [""]
    demos = _load(ARCHIVE / "cpu_3000_reach_demos" / "results.json")
    if demos:
        parts += generalisation_section(demos, "archive/cpu_3000_reach_demos")
    for path in sorted(ARCHIVE.glob("ablation_cpu*.json")):
        ablation = _load(path)
        if ablation and ablation.get("rows"):
            parts += ablation_section(ablation, f"archive/{path.name}") + [""]
    for path in sorted(ARCHIVE.glob("validation_curve_*.json")):
        parts += validation_curve_section(_load(path), f"archive/{path.name}") + [""]
    text = "\n".join(parts).rstrip() + "\n"
    for old, new in _ARCHIVE_LINKS:
        text = text.replace(old, new)
    return text


def render_doc(text: str) -> str:
    """docs/BENCHMARKS.md with its generated block replaced (or put after the title when it has none)."""
    block = "\n".join(current_block())
    if START in text and END in text:
        return text[: text.index(START)] + block + text[text.index(END) + len(END) :]
    head, _, rest = text.partition("\n\n")
    return head + "\n\n" + block + "\n\n" + rest


def main() -> int:
    DOC.write_text(render_doc(DOC.read_text()))
    ARCHIVE_DOC.write_text(archive_page())
    print(f"wrote the current results of {DOC} and {ARCHIVE_DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
