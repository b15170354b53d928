#!/usr/bin/env python
"""Write the CPU-results section of docs/BENCHMARKS.md from the committed JSON.

Nothing in that section is typed by hand: it is rebuilt from

  benchmarks/results/train_step_cpu.json    benchmarks/bench_train_step.py (where a training step goes)
  benchmarks/results/cpu/results.json       benchmarks/run_benchmark.py --scale cpu (success vs ACT / DP)
  benchmarks/results/cpu_3000/results.json  the same at 3,000 training steps (--steps 3000 --out ...cpu_3000)
  benchmarks/results/ablation_cpu*.json     benchmarks/run_ablation.py [--out ...] (validation seeds, reach-v3)
  benchmarks/results/validation_curve_*.json  benchmarks/validation_curve.py (success against training step)
  benchmarks/results/cpu/train_placements.json  benchmarks/eval_train_placements.py (do policies fit their demos?)
  benchmarks/results/cpu_reach_hand_expert/   reach-v3 runs on the earlier demos (MetaWorld's hand-target expert)
  benchmarks/results/quickstart*_cpu.json   examples/quickstart.sh's summary.json, copied (one per task)
  benchmarks/results/inference_cpu_tier.json  benchmarks/bench_inference.py --configs cpu (chunk latency)
  benchmarks/results/one_step_sampling*.json  benchmarks/sampler_steps.py (1 vs 4 denoising steps, same episodes)
  benchmarks/results/device_check_*.json    benchmarks/device_check.py (GPU lease)

whichever exist, between the markers `<!-- cpu-results:start -->` and `<!-- cpu-results:end -->`; the plots of
the CPU benchmark are copied to docs/images/.

    python benchmarks/write_benchmarks_md.py
"""

import json
import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
RESULTS = REPO / "benchmarks" / "results"
DOC = REPO / "docs" / "BENCHMARKS.md"
START, END = "<!-- cpu-results:start -->", "<!-- cpu-results:end -->"


def _load(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


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


def cpu_benchmark_section(res: dict, folder: str = "cpu", images: str = "cpu") -> list[str]:
    b = res["benchmark"]
    runs = res["runs"]
    steps = res["settings"]["matched"]["steps"]
    command = b.get("command", "")
    if "benchmarks/run_benchmark.py" in command:  # the invocation that wrote results.json, interpreter dropped
        command = "python benchmarks/run_benchmark.py" + command.split("benchmarks/run_benchmark.py", 1)[1]
    else:
        command = ("python benchmarks/run_benchmark.py --scale cpu --tasks " + ",".join(b["tasks"]) + " --methods "
                   + ",".join(b["methods"]) + f" --steps {steps} --out benchmarks/results/{folder} --resume")
    switches = [spec.partition(":")[2] for spec in b.get("train_arg") or []]
    title = f"CPU scale, {steps} training steps" + (f", R&D trained with `{' '.join(switches)}`" if switches else "")
    lines = [
        f"### R&D vs ACT vs Diffusion Policy on MetaWorld ({title}): `benchmarks/results/{folder}`",
        "",
        f"`{command}` (each run's exact lerobot-train / lerobot-eval commands are in its JSON)",
        "",
        (("Trained only (`--train-only`): not evaluated on the evaluation seeds; its validation-seed result, if "
          "any, is in the ablation tables below. ") if "--train-only" in command else "") +
        f"{'Complete' if b['complete'] else '**Incomplete**: the runs listed as pending were not done in this session'}. "
        f"Written {b['written']}. {res['settings']['matched']['steps']} training steps of batch "
        f"{res['settings']['matched']['batch_size']} for every method, demos recorded with seed "
        f"{res['settings']['record_seed']}, evaluation seeds from {res['settings']['eval_seed']} "
        f"({res['settings']['eval_episodes_per_cell']} episodes per cell, {res['settings']['episode_length']}-step "
        "episodes, `lerobot-eval --env.type=rnd_mw`). Success rate with its Wilson 95% interval. "
        + (f"JSON per run: [`benchmarks/results/{folder}/runs/`](../benchmarks/results/{folder}/runs/); "
           if (RESULTS / folder / "runs").is_dir() else "") +
        "All runs: "
        f"[`benchmarks/results/{folder}/results.json`](../benchmarks/results/{folder}/results.json)." +
        (f" {_collected_sentence(runs, folder)}" if any(r.get("collected_from") for r in runs) else ""),
        "",
        "| method | task | demos | success | 95% interval | episodes | params | train loop | eval | final loss |",
        "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    notes = []
    for r in runs:
        run_json = (REPO / r["collected_from"] if r.get("collected_from") else
                    RESULTS / folder / "runs" / f"{r['method']}__{r['task']}__n{r['demos']}__seed{r.get('seed', 0)}.json")  # fmt: skip
        note = (_load(run_json) or {}).get("note")
        if note:  # runs that share a note share its footnote
            if note not in notes:
                notes.append(note)
            r = {**r, "label": f"{r['label']} [{notes.index(note) + 1}]"}
        if not r["eval_episodes"]:
            curve = r.get("loss_curve") or []
            final = f"{curve[-1][1]:.3f}" if curve else "–"
            lines.append(f"| {r['label']} | {r['task']} | {r['demos']} | not evaluated | | | | | | {final} |")
            continue
        lo, hi = r["ci95"]
        curve = r.get("loss_curve") or []
        final = f"{curve[-1][1]:.3f}" if curve else "–"
        params = f"{r['n_params'] / 1e6:.1f}M" if r.get("n_params") else "–"
        tl = f"{r['train_seconds'] / 60:.1f} min" if r.get("train_seconds") else "–"
        ev = f"{r['eval_seconds'] / 60:.1f} min" if r.get("eval_seconds") else "–"
        lines.append(
            f"| {r['label']} | {r['task']} | {r['demos']} | {100 * r['success_rate']:.0f}% | "
            f"{100 * lo:.0f}–{100 * hi:.0f}% | {r['eval_episodes']} | {params} | {tl} | {ev} | {final} |"
        )
    lines += [""] + [f"[{i}] {n}" for i, n in enumerate(notes, 1)]
    lines += [
        "",
        f"![success per task](images/{images}_success_per_task.png)",
        "",
        *([f"![success against the number of demos](images/{images}_success_vs_demos.png)", ""]
          if len(res["benchmark"]["demos"]) > 1 else []),
        "Training loss curves (each method's own loss; did it flatten?):",
        "",
        f"![loss curves](images/{images}_loss_curves.png)",
    ]
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


def _collected_sentence(runs: list[dict], folder: str) -> str:
    """Where the runs that another benchmark trained come from (run_benchmark.py --collect-from)."""
    collected = [r for r in runs if r.get("collected_from")]
    sources = sorted({Path(r["collected_from"]).parent.parent.name for r in collected})
    own = "trains nothing" if len(collected) == len(runs) else f"trains {len(runs) - len(collected)} of its runs"
    count = f"{len(collected)} run is" if len(collected) == 1 else f"{len(collected)} runs are"
    return (f"This folder {own}: {count} read from "
            + ", ".join(f"[`{s}`](../benchmarks/results/{s}/)" for s in sources)
            + f" (`--collect-from`; [`results.md`](../benchmarks/results/{folder}/results.md) names each run's "
            "source), so the command above trains only what none of them holds.")


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
        res["description"] + " JSON: [`benchmarks/results/cpu_reach_hand_expert/`](../benchmarks/results/cpu_reach_hand_expert/).",
        "",
        "| method | task | success | 95% interval | episodes |",
        "| --- | --- | ---: | --- | ---: |",
    ]
    for r in res["runs"]:
        lo, hi = r["ci95"]
        lines.append(f"| {r['label']} | {r['task']} | {r['successes']}/{r['eval_episodes']} | "
                     f"{100 * lo:.0f}–{100 * hi:.0f}% | {r['eval_episodes']} |")  # fmt: skip
    if fit:
        lines += [""] + train_placements_section(fit, "benchmarks/results/cpu_reach_hand_expert/train_placements.json")[2:]
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


def main() -> int:
    parts = [START, "", "## CPU results (generated by `benchmarks/write_benchmarks_md.py` from the JSON)", ""]
    for path in sorted(RESULTS.glob("train_step_cpu*.json")):  # one per machine kind (AVX-512, AVX2)
        train = _load(path)
        if train:
            parts += train_step_section(train, path.name) + [""]
    quick = [(p.name, _load(p)) for p in sorted(RESULTS.glob("quickstart*_cpu.json"))]
    if quick:
        parts += quickstart_section(quick) + [""]
    for path in sorted(RESULTS.glob("inference_cpu_tier*.json")):  # one per machine kind (AVX2, AVX-512)
        inference = _load(path)
        if inference:
            parts += inference_section(inference, path.name) + [""]
    for folder in sorted(p.parent.name for p in RESULTS.glob("cpu*/results.json")):
        bench = _load(RESULTS / folder / "results.json")
        if bench:
            parts += cpu_benchmark_section(bench, folder, folder) + [""]
            parts += generalisation_section(bench, folder)
            for name in ("success_per_task", "loss_curves") + (("success_vs_demos",) if len(bench["benchmark"]["demos"]) > 1 else ()):
                src = RESULTS / folder / f"{name}.png"
                if src.exists():
                    shutil.copy(src, REPO / "docs" / "images" / f"{folder}_{name}.png")
    fit = _load(RESULTS / "cpu" / "train_placements.json")
    if fit:
        parts += train_placements_section(fit, "benchmarks/results/cpu/train_placements.json") + [""]
    hand = _load(RESULTS / "cpu_reach_hand_expert" / "results_reach.json")
    if hand:
        parts += hand_expert_section(hand, _load(RESULTS / "cpu_reach_hand_expert" / "train_placements.json")) + [""]
    for path in sorted(RESULTS.glob("ablation_cpu*.json")):
        ablation = _load(path)
        if ablation and ablation.get("rows"):  # a file whose first row is still training has none yet
            parts += ablation_section(ablation, path.name) + [""]
    for path in sorted(RESULTS.glob("one_step_sampling*.json")):
        steps = _load(path)
        if steps and steps.get("entries"):  # the first, hand-assembled validation file has "runs" instead
            parts += sampler_steps_section(steps, path.name) + [""]
    for path in sorted(RESULTS.glob("validation_curve_*.json")):
        parts += validation_curve_section(_load(path), path.name) + [""]
        if path.with_suffix(".png").exists():
            shutil.copy(path.with_suffix(".png"), REPO / "docs" / "images" / path.with_suffix(".png").name)
    parts.append(END)
    text = DOC.read_text()
    block = "\n".join(parts)
    if START in text and END in text:
        text = text[: text.index(START)] + block + text[text.index(END) + len(END) :]
    else:
        head, _, rest = text.partition("\n\n")
        text = head + "\n\n" + block + "\n\n" + rest
    DOC.write_text(text)
    print(f"wrote the CPU-results section of {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
