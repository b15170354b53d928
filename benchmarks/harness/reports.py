"""Reports, pure functions of results.json: Wilson intervals, per-cell statistics, where R&D loses, results.md
and the plots (success vs demos, success per task, loss curves, spatial heat maps)."""

from __future__ import annotations

import math
import re
from pathlib import Path

from .scales import METHODS, RND_METHODS


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (95% by default); (nan, nan) for n = 0."""
    if n <= 0:
        return (float("nan"), float("nan"))
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # exact ends for 0/n and n/n (the formula leaves a rounding error there, which once made a plot's error bar
    # negative)
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return (lo, hi)


_LOG_LINE = re.compile(r"^\$ |step:([0-9.]+)([KMBT]?) .*?loss:([0-9.]+)", re.MULTILINE)
_SUFFIX = {"": 1, "K": 10**3, "M": 10**6, "B": 10**9, "T": 10**12}
_CFG_STEPS = re.compile(r"cfg\.steps=(\d+)")
_PROGRESS_BAR = re.compile(r"Training:\s+\d+%\|[^|\n\r]*\|\s*\d+/(\d+) \[")


def median_logged(text: str, key: str) -> float | None:
    """Median (upper middle) of a value lerobot-train logs as `key:<number>` (e.g. `updt_s`, `data_s`)."""
    m = [float(x) for x in re.findall(rf"{re.escape(key)}:([0-9.]+)", text)]
    return sorted(m)[len(m) // 2] if m else None


def median_update_s_from_log(text: str) -> float | None:
    """Median of lerobot-train's logged `updt_s` (seconds per optimiser step, data loading excluded)."""
    return median_logged(text, "updt_s")


def loss_curve_from_log(text: str, log_freq: int) -> list[tuple[int, float]]:
    """[(step, loss)] from a lerobot-train log (the harness's train.log may hold several invocations).

    LeRobot prints the step rounded to thousands ('step:2K' for 1,500-2,499), so each logged line's step is the
    previous line's plus `log_freq`. Each invocation (a line starting with '$ ', as the harness writes before every
    command) anchors the count at its first logged line: at the step it resumed from, when the invocation logged
    both `cfg.steps=S` and its progress bar's 'k/T' (LeRobot's bar counts the T = S - start steps left), so the
    first line is the next multiple of `log_freq` after the start; else at the printed value (exact below 1,000,
    within 500 above). A step logged twice keeps its last loss.
    """
    curve: dict[int, float] = {}
    for invocation in re.split(r"^(?=\$ )", text, flags=re.MULTILINE):
        total = _CFG_STEPS.search(invocation)
        bar = _PROGRESS_BAR.search(invocation)
        start = int(total.group(1)) - int(bar.group(1)) if total and bar else None
        step = None
        for m in _LOG_LINE.finditer(invocation):
            if m.group(0).startswith("$"):
                continue
            if step is None:
                shown = round(float(m.group(1)) * _SUFFIX[m.group(2)])
                step = shown if start is None else (start // log_freq + 1) * log_freq
            else:
                step += log_freq
            curve[step] = float(m.group(3))
    return sorted(curve.items())


def _pool(runs: list[dict]) -> tuple[int, int]:
    return sum(r["successes"] for r in runs), sum(r["eval_episodes"] for r in runs)


def cell_stats(runs: list[dict], method: str, task: str | None, demos: int | None) -> dict | None:
    sel = [r for r in runs if r["method"] == method and r["eval_episodes"] > 0
           and (task is None or r["task"] == task) and (demos is None or r["demos"] == demos)]  # fmt: skip
    if not sel:
        return None
    k, n = _pool(sel)
    lo, hi = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n, "lo": lo, "hi": hi}


def rnd_losses(runs: list[dict]) -> list[dict]:
    """Every (task, demos) cell where a baseline's success rate beats an R&D variant's."""
    out = []
    cells = sorted({(r["task"], r["demos"]) for r in runs})
    methods = sorted({r["method"] for r in runs})
    for task, n in cells:
        for rv in [m for m in methods if m in RND_METHODS]:
            s = cell_stats(runs, rv, task, n)
            if s is None:
                continue
            for b in [m for m in methods if m not in RND_METHODS]:
                t = cell_stats(runs, b, task, n)
                if t is None or t["rate"] <= s["rate"]:
                    continue
                out.append({"task": task, "demos": n, "rnd": rv, "baseline": b,
                            "rnd_rate": s["rate"], "baseline_rate": t["rate"],
                            "significant": bool(t["lo"] > s["hi"])})  # fmt: skip
    return out


def _fmt_cell(s: dict | None) -> str:
    if s is None:
        return "–"
    return f"{100 * s['rate']:.0f}% [{100 * s['lo']:.0f}–{100 * s['hi']:.0f}] ({s['k']}/{s['n']})"


def _fmt_s(x) -> str:
    if x is None:
        return "–"
    return f"{x:.0f} s" if x < 600 else f"{x / 60:.1f} min"


def _episodes_per_cell(settings: dict) -> str:
    """results.md's episodes per cell: a count (random protocol) or the spatial protocol's 'one per valid grid
    point', as a phrase."""
    n = settings["eval_episodes_per_cell"]
    if isinstance(n, str):
        return n.replace("one per", "one episode per", 1)
    return f"{n} episodes per cell"


def markdown_report(res: dict) -> str:
    b, runs, st = res["benchmark"], res["runs"], res["settings"]
    cells = [(t, n) for t in b["tasks"] for n in b["demos"]]
    suite = "" if b.get("suite", "metaworld") == "metaworld" else f" ({b['suite']} suite)"
    lines = [
        f"# Benchmark{suite}: {b['scale']} scale, {b['protocol']} protocol",
        "",
        f"{'Complete' if b['complete'] else '**Incomplete** (run again with `--resume`)'}; written "
        f"{b['written']} on {b['host']['platform']} ({b['host']['cpus']} CPUs"
        f"{', ' + b['host']['cuda'] if b['host']['cuda'] else ''}), torch {b['host']['torch']}, "
        f"lerobot {b['host']['lerobot']}.",
        "",
        f"Success rate, Wilson 95% interval, (successes / episodes). Training seeds {b['seeds']}; "
        f"{st['matched']['steps']} steps of batch {st['matched']['batch_size']}; demos recorded with seed "
        f"{st['record_seed']}; evaluation seeds from {st['eval_seed']} ({_episodes_per_cell(st)}, "
        f"{st['episode_length']}-step episodes).",
    ]
    if b.get("multitask"):
        lines += ["", f"**Multi-task** (`--multitask`): per method and demo count, one policy trained on all "
                  f"{len(b['tasks'])} tasks together ({', '.join(b['tasks'])}; the demo count is per task) and "
                  "evaluated on each; training and evaluation cost are counted once per run."]  # fmt: skip
    if b["scale"] == "smoke":
        lines += ["", "**Smoke scale: tiny models trained for a few steps. These numbers test the pipeline; "
                  "they say nothing about the methods.**"]  # fmt: skip
    lines += ["", "| method | " + " | ".join(f"{t} / {n} demos" for t, n in cells) + " | average |",
              "| --- |" + " --- |" * (len(cells) + 1)]  # fmt: skip
    for m in b["methods"]:
        row = [_fmt_cell(cell_stats(runs, m, t, n)) for t, n in cells]
        row.append(_fmt_cell(cell_stats(runs, m, None, None)))
        lines.append(f"| {METHODS[m][1]} | " + " | ".join(row) + " |")
    collected = [r for r in runs if r.get("collected_from")]
    if collected:
        lines += ["", f"{len(collected)} of the {len(runs)} runs were trained and evaluated by other benchmarks and "
                  "collected here (`--collect-from`; each run's JSON holds its own commands):", ""]  # fmt: skip
        lines += [f"- {METHODS[r['method']][1]} / {r['task']} / {r['demos']} demos / seed {r['seed']}: "
                  f"`{r['collected_from']}`" for r in collected]  # fmt: skip
    lines += ["", "## Training and evaluation cost", "",
              "| method | parameters | training loop (sum over runs) | training wall incl. start-up | "
              "evaluation wall | runs done |", "| --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    for m in b["methods"]:
        rs = [r for r in runs if r["method"] == m]
        params = sorted({r["n_params"] for r in rs if r["n_params"]})
        ptxt = ", ".join(f"{p / 1e6:.2f}M" for p in params) or "–"
        tl = [r["train_seconds"] for r in rs if r["train_seconds"] is not None]
        tw = [r["train_wall_seconds"] for r in rs if r["train_wall_seconds"] is not None]
        ev = [r["eval_seconds"] for r in rs if r["eval_seconds"]]
        done = sum(r["status"] == "done" for r in rs)
        lines.append(f"| {METHODS[m][1]} | {ptxt} | {_fmt_s(sum(tl)) if tl else '–'} | "
                     f"{_fmt_s(sum(tw)) if tw else '–'} | {_fmt_s(sum(ev)) if ev else '–'} | {done}/{len(rs)} |")  # fmt: skip
    lines += ["", "## Where R&D loses", ""]
    losses = res.get("rnd_losses", [])
    if not losses:
        lines.append("No cell where a baseline's success rate is above an R&D variant's.")
    else:
        lines.append("Cells where a baseline's success rate is above an R&D variant's; *significant* = the "
                     "baseline's Wilson interval lies entirely above R&D's.")  # fmt: skip
        lines.append("")
        for x in losses:
            lines.append(f"- {x['task']} / {x['demos']} demos: {METHODS[x['baseline']][1]} "
                         f"{100 * x['baseline_rate']:.0f}% > {METHODS[x['rnd']][1]} {100 * x['rnd_rate']:.0f}%"
                         f"{' (significant)' if x['significant'] else ' (within the intervals)'}")  # fmt: skip
    failed = [r for r in runs if r["status"] == "failed"]
    pending = [r for r in runs if r["status"] not in ("done", "failed")]
    if failed or pending:
        lines += ["", "## Not done", ""]
        for r in failed:
            err = (r.get("error") or "").strip().splitlines()
            lines.append(f"- FAILED {r['method']} / {r['task']} / {r['demos']} demos / seed {r['seed']}: "
                         f"`{err[0][:200] if err else '?'}` (full log tail in results.json)")  # fmt: skip
        for r in pending:
            lines.append(f"- pending {r['method']} / {r['task']} / {r['demos']} demos / seed {r['seed']} "
                         f"({r['steps_done']}/{r['steps']} steps, {r['eval_episodes']} episodes evaluated)")
    lines += ["", "## Settings", ""]
    for k, v in st["matched"].items():
        lines.append(f"- {k}: {v}")
    lines.append(f"- evaluation placements: {st['eval_placements']}")
    if st.get("demo_placements"):
        lines.append(f"- demo placements: {st['demo_placements']}")
    for t, es in res.get("eval_sets", {}).items():
        if "cells" in es:
            shape = " x ".join(str(len(es[k])) for k in ("grid_x", "grid_y", "grid_z") if k in es)
            lines.append(f"- {t}: {shape} grid over placement coordinates {es['grid_dims']}: {len(es['cells'])} "
                         f"cells evaluated, {es.get('n_invalid', 0)} invalid skipped")  # fmt: skip
    for t, es in res.get("eval_sets", {}).items():
        if "min_normalised_distance_to_train" in es:
            lines.append(f"- {t}: {len(es['placements'])} evaluation placements, none equal to a training one "
                         f"({es['n_equal_to_a_train_placement']} equal); nearest training placement at normalised "
                         f"distance {es['min_normalised_distance_to_train']:.3f} (median "
                         f"{es['median_normalised_distance_to_train']:.3f})")  # fmt: skip
    for t, ds in res.get("datasets", {}).items():
        for n, d in ds.items():
            pre = d.get("prefix_of_next")
            lines.append(f"- data {t} / {n} demos: `{d['root']}`, {d['frames']} frames"
                         f"{'; first episodes of the next larger set' if pre else ''}"
                         f"{'; NOT a prefix of the next larger set' if pre is False else ''}")  # fmt: skip
    lines.append("- per-method lerobot-train overrides (besides the config file):")
    for m, args in st["method_args"].items():
        lines.append(f"  - {METHODS[m][1]} (`{st['config_files'][m]}`): `{' '.join(args)}`")
    lines += ["", "Every command, per-episode outcome and seed is in `results.json`.", ""]
    return "\n".join(lines)


def _mpl():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_success_vs_demos(res: dict, path: Path) -> list[str]:
    """Success against demo count with Wilson 95% bars, one panel per task (and the average), one colour per
    method in every panel; returns the legend's labels."""
    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    panels = list(b["tasks"]) + (["average"] if len(b["tasks"]) > 1 else [])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), squeeze=False)
    for ax, panel in zip(axes[0], panels, strict=True):
        for j, m in enumerate(b["methods"]):
            xs, ys, lo, hi = [], [], [], []
            for n in sorted(b["demos"]):
                s = cell_stats(runs, m, None if panel == "average" else panel, n)
                if s is None:
                    continue
                xs.append(n + (j - (len(b["methods"]) - 1) / 2) * 0.15 * (1 if len(b["demos"]) == 1 else 1))
                ys.append(100 * s["rate"])
                # max(0, .): the Wilson bound of 0/n (or n/n) can fall a rounding error past the rate
                lo.append(max(0.0, 100 * (s["rate"] - s["lo"])))
                hi.append(max(0.0, 100 * (s["hi"] - s["rate"])))
            if xs:
                ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=METHODS[m][1], color=f"C{j}",
                            linestyle="-" if len(xs) > 1 else "none")  # fmt: skip
        ax.set_title(panel)
        ax.set_xlabel("demonstrations")
        ax.set_xticks(sorted(b["demos"]))
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success rate (%), Wilson 95%")
    labels = _legend_of_all_panels(axes[0], fontsize=8)
    title = f"{b['scale']} scale, {b['protocol']} protocol"
    if b["scale"] == "smoke":
        title += " (pipeline check, not a result)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return labels


def _legend_of_all_panels(axes, fontsize: int) -> list[str]:
    """One legend, right of the last panel, listing every label drawn in any panel once (a method or run that only
    one panel shows still gets its entry); returns the labels in legend order."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    if entries:
        axes[-1].legend(list(entries.values()), list(entries), fontsize=fontsize, loc="upper left",
                        bbox_to_anchor=(1.02, 1.0))  # fmt: skip
    return list(entries)


def success_bars(res: dict) -> tuple[list[str], dict[str, list[tuple[int, dict]]]]:
    """The bars of `plot_success_per_task`: the panels (tasks, then "mean over tasks" when there are several) and,
    per method, (panel index, cell) pairs. A cell pools every demo count; the mean panel pools every episode of
    the benchmark's tasks, as the tables' "average" column does, with its Wilson interval. A method missing a
    task has no mean bar."""
    b, runs = res["benchmark"], res["runs"]
    panels = list(b["tasks"]) + (["mean over tasks"] if len(b["tasks"]) > 1 else [])
    bars: dict[str, list[tuple[int, dict]]] = {}
    for m in b["methods"]:
        bars[m] = []
        for i, panel in enumerate(panels):
            if panel == "mean over tasks":
                if any(cell_stats(runs, m, t, None) is None for t in b["tasks"]):
                    continue
                s = cell_stats([r for r in runs if r["task"] in b["tasks"]], m, None, None)
            else:
                s = cell_stats(runs, m, panel, None)
            if s is not None:
                bars[m].append((i, s))
    return panels, bars


def plot_success_per_task(res: dict, path: Path) -> None:
    """Bars: success per task (and the mean over tasks) per method, Wilson 95% intervals, all demo counts pooled."""
    plt = _mpl()
    b = res["benchmark"]
    panels, bars = success_bars(res)
    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(panels) * max(1, len(b["methods"])) / 3, 3.6))
    width = 0.8 / max(1, len(b["methods"]))
    for j, m in enumerate(b["methods"]):
        xs = [i + (j - (len(b["methods"]) - 1) / 2) * width for i, _ in bars[m]]
        ys = [100 * s["rate"] for _, s in bars[m]]
        lo = [max(0.0, 100 * (s["rate"] - s["lo"])) for _, s in bars[m]]
        hi = [max(0.0, 100 * (s["hi"] - s["rate"])) for _, s in bars[m]]
        if xs:
            ax.bar(xs, ys, width=width, yerr=[lo, hi], capsize=3, label=METHODS[m][1])
    ax.set_xticks(range(len(panels)))
    ax.set_xticklabels(panels, fontsize=8)
    ax.set_ylim(0, 105)
    ax.set_ylabel("success rate (%), Wilson 95%")
    ax.grid(axis="y", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    ax.set_title(f"{b['scale']} scale: {', '.join(str(n) for n in b['demos'])} demos, "
                 f"{b['protocol']} placements", fontsize=9)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_loss_curves(res: dict, path: Path) -> list[str]:
    """Training loss against step, one panel per task, one line per run (each method's own loss): a colour per
    method and a line style per demo count, the same in every panel; returns the legend's labels."""
    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    tasks = [t for t in b["tasks"] if any(r.get("loss_curve") and r["task"] == t for r in runs)]
    if not tasks:
        return []
    methods = list(b["methods"])
    demo_counts = sorted({r["demos"] for r in runs})
    styles = ["-", "--", ":", "-."]
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), squeeze=False)
    for ax, task in zip(axes[0], tasks, strict=True):
        for r in runs:
            if r["task"] != task or not r.get("loss_curve"):
                continue
            steps, losses = zip(*r["loss_curve"])
            ax.plot(steps, losses, label=f"{METHODS[r['method']][1]} (n{r['demos']}, s{r['seed']})",
                    color=f"C{methods.index(r['method']) if r['method'] in methods else len(methods)}",
                    linestyle=styles[demo_counts.index(r["demos"]) % len(styles)])  # fmt: skip
        ax.set_yscale("log")
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("training step")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("training loss (each method's own)")
    labels = _legend_of_all_panels(axes[0], fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return labels


def plot_heatmap(res: dict, task: str, path: Path) -> None:
    """Success over the evaluation grid (rows: methods, columns: demo counts), training placements marked."""
    import numpy as np

    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    es = res["eval_sets"].get(task)
    if not es or "cells" not in es:
        return
    if len(es["grid_dims"]) == 3:
        return plot_heatmap_3d(res, task, path)
    G = len(es["grid_x"])
    dims = es["grid_dims"]
    ms, ns = b["methods"], sorted(b["demos"])
    fig, axes = plt.subplots(len(ms), len(ns), figsize=(max(5.0, 3.0 * len(ns) + 1.2), 2.7 * len(ms) + 0.6),
                             squeeze=False)  # fmt: skip
    gx, gy = es["grid_x"], es["grid_y"]
    hx = (gx[-1] - gx[0]) / max(1, G - 1) / 2
    hy = (gy[-1] - gy[0]) / max(1, G - 1) / 2
    ext = [gx[0] - hx, gx[-1] + hx, gy[0] - hy, gy[-1] + hy]  # cell centres on the grid points
    for i, m in enumerate(ms):
        for j, n in enumerate(ns):
            ax = axes[i][j]
            grid = np.full((G, G), np.nan)
            sel = [r for r in runs if r["method"] == m and r["task"] == task and r["demos"] == n]
            if sel and all(len(r["per_episode_success"]) == len(es["cells"]) for r in sel):
                acc = np.mean([r["per_episode_success"] for r in sel], axis=0)
                for (iy, ix), v in zip(es["cells"], acc, strict=True):
                    grid[iy, ix] = v
            im = ax.imshow(grid, origin="lower", extent=ext, vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
            tr = res["datasets"].get(task, {}).get(str(n), {}).get("placements", [])
            if tr:
                tr = np.asarray(tr)
                ax.scatter(tr[:, dims[0]], tr[:, dims[1]], marker="x", c="k", s=18, label="demos")
            s = cell_stats(runs, m, task, n)
            ax.set_title(f"{METHODS[m][1]}, {n} demos: {_fmt_cell(s).split(' (')[0]}", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.set_xlabel(f"placement[{dims[0]}] (m)", fontsize=7)
            ax.set_ylabel(f"placement[{dims[1]}] (m)", fontsize=7)
    fig.subplots_adjust(top=1.0 - 0.85 / fig.get_figheight(), hspace=0.45, wspace=0.35)
    fig.colorbar(im, ax=axes, shrink=0.6, label="success")
    fig.suptitle(f"{task}: success per evaluation placement\n(x: training placements; grid over placement "
                 f"coordinates {dims[0]}, {dims[1]})", fontsize=8)  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _deg(rad: float) -> str:
    return f"{math.degrees(rad):+.0f}°"


def _label_offsets(x, y, ext, near: float = 0.08, step: float = 6.0) -> list[tuple[float, float]]:
    """Text offsets (points) for labels next to the marks at (x, y) on a map spanning ``ext`` = [x0, x1, y0, y1]:
    each label on the side towards the middle of the map, 3 points from its mark; a mark within ``near`` (a fraction
    of the map's width and height) of earlier ones has its label pushed ``step`` points further per such mark, away
    from them in y, so the labels of demos placed close together do not print over each other."""
    span = (max(ext[1] - ext[0], 1e-12), max(ext[3] - ext[2], 1e-12))
    offsets: list[tuple[float, float]] = []
    for i in range(len(x)):
        right = x[i] <= (ext[0] + ext[1]) / 2
        up = y[i] <= (ext[2] + ext[3]) / 2
        crowd = sum(abs(x[i] - x[j]) / span[0] < near and abs(y[i] - y[j]) / span[1] < near for j in range(i))
        dy = 3 + step * crowd
        offsets.append((3.0 if right else -3.0, dy if up else -dy))
    return offsets


def _direction_arrows(ax, x, y, d, length: float, color: str) -> None:
    """Arrows of one ``length`` (data units) from the points (x, y) along the (N, 2) directions ``d``."""
    import numpy as np

    u = np.asarray(d, dtype=float)
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-9) * length
    ax.quiver(x, y, u[:, 0], u[:, 1], angles="xy", scale_units="xy", scale=1, color=color, width=0.008,
              alpha=0.8, zorder=3)  # fmt: skip


def plot_heatmap_3d(res: dict, task: str, path: Path) -> list[str]:
    """Success over a 3-D evaluation grid (x, y and yaw: Panda's object pose): one x-y heat map per yaw value
    (rows: method x yaw, columns: demo counts), the training placements' (x, y) marked with their yaw written next
    to them; for a task with a target (push-block, pick-place, slide-block) an arrow per cell and demo towards it.
    Returns the panels' titles (each names its yaw)."""
    import numpy as np

    from lerobot_rnd.sim.panda_scene import placement_target_xy

    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    es = res["eval_sets"][task]
    dims = es["grid_dims"]
    gx, gy, gz = es["grid_x"], es["grid_y"], es["grid_z"]
    G, Gy, Z = len(gx), len(gy), len(gz)
    ms, ns = b["methods"], sorted(b["demos"])
    # where each cell and demo pushes or carries its object to (the target's (x, y), from the placement)
    def to_target(P: np.ndarray) -> np.ndarray:
        return np.stack([placement_target_xy(task, p) for p in P]) - P[:, :2]

    targets = bool(es["placements"]) and placement_target_xy(task, es["placements"][0]) is not None
    hx = (gx[-1] - gx[0]) / max(1, G - 1) / 2
    hy = (gy[-1] - gy[0]) / max(1, Gy - 1) / 2
    ext = [gx[0] - hx, gx[-1] + hx, gy[0] - hy, gy[-1] + hy]
    fig, axes = plt.subplots(len(ms) * Z, len(ns), figsize=(max(6.5, 3.0 * len(ns) + 1.2), 2.7 * len(ms) * Z + 1.0),
                             squeeze=False)  # fmt: skip
    titles, im = [], None
    for i, m in enumerate(ms):
        for j, n in enumerate(ns):
            sel = [r for r in runs if r["method"] == m and r["task"] == task and r["demos"] == n]
            acc = None
            if sel and all(len(r["per_episode_success"]) == len(es["cells"]) for r in sel):
                acc = np.mean([r["per_episode_success"] for r in sel], axis=0)
            tr = np.asarray(res["datasets"].get(task, {}).get(str(n), {}).get("placements", []), dtype=float)
            for iz, z in enumerate(gz):
                ax = axes[i * Z + iz][j]
                grid = np.full((Gy, G), np.nan)
                k = cnt = 0
                if acc is not None:
                    for (iy, ix, cz), v in zip(es["cells"], acc, strict=True):
                        if cz == iz:
                            grid[iy, ix] = v
                            k, cnt = k + v, cnt + 1
                im = ax.imshow(grid, origin="lower", extent=ext, vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
                if targets:  # each cell's direction from the object to its target
                    here = [k for k, c in enumerate(es["cells"]) if c[2] == iz]
                    if here:
                        P = np.asarray([es["placements"][k] for k in here], dtype=float)
                        _direction_arrows(ax, P[:, dims[0]], P[:, dims[1]], to_target(P), 0.7 * min(hx, hy), "k")
                    if len(tr):
                        _direction_arrows(ax, tr[:, dims[0]], tr[:, dims[1]], to_target(tr), 0.45 * min(hx, hy), "navy")
                if len(tr):
                    ax.scatter(tr[:, dims[0]], tr[:, dims[1]], marker="x", c="k", s=18, label="demos")
                    offsets = _label_offsets(tr[:, dims[0]], tr[:, dims[1]], ext)
                    for p, (ox, oy) in zip(tr, offsets, strict=True):  # the yaw next to the mark
                        ax.annotate(_deg(p[dims[2]]), (p[dims[0]], p[dims[1]]), fontsize=5, xytext=(ox, oy),
                                    textcoords="offset points", ha="left" if ox > 0 else "right",
                                    va="bottom" if oy > 0 else "top")  # fmt: skip
                rate = f"{100 * k / cnt:.0f}% of {cnt}" if cnt else "–"
                title = f"{METHODS[m][1]}, {n} demos, yaw {_deg(z)}: {rate}"
                titles.append(title)
                ax.set_title(title, fontsize=7)
                ax.tick_params(labelsize=6)
                ax.set_xlabel(f"placement[{dims[0]}] x (m)", fontsize=7)
                ax.set_ylabel(f"placement[{dims[1]}] y (m)", fontsize=7)
    header_in = 1.0 + (0.25 if targets else 0.0)  # the suptitle's lines, inches
    fig.subplots_adjust(top=1.0 - header_in / fig.get_figheight(), hspace=0.55, wspace=0.35)
    fig.colorbar(im, ax=axes, shrink=0.6, label="success")
    fig.suptitle(f"{task}: success per evaluation placement,\none x-y map per yaw (placement[{dims[2]}]: "
                 f"{', '.join(_deg(z) for z in gz)})\nx: training placements, their yaw written; "
                 + ("\narrows: direction to the target (black: test cell, blue: demo); " if targets else "")
                 + f"{es.get('n_invalid', 0)} invalid cells skipped", fontsize=8)  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return titles


def write_report_files(res: dict, out: Path) -> None:
    """results.md and the plots of ``res`` into ``out`` (heat maps under the spatial protocol)."""
    (out / "results.md").write_text(markdown_report(res))
    plot_success_vs_demos(res, out / "success_vs_demos.png")
    plot_success_per_task(res, out / "success_per_task.png")
    plot_loss_curves(res, out / "loss_curves.png")
    if res["benchmark"]["protocol"] == "spatial":
        for task in res["benchmark"]["tasks"]:
            plot_heatmap(res, task, out / f"heatmap_{task}.png")
