#!/usr/bin/env python
"""Which evaluation episodes each ablation row solves, against a reference row.

A row's success rate hides whether a lever solves *other* episodes or the same ones. This script reads an
ablation JSON (`run_ablation.py`'s, every row with `per_episode_success` on the same seeds), prints per row its
successes, how many it shares with the reference row and how many only it solves, then per episode how many rows
solve it. With `--trace` (a `trace_rollouts.py` JSON on the same seeds) each episode also shows its goal.

    python benchmarks/episode_overlap.py --ablation benchmarks/results/archive/ablation_cpu_tcp_3000.json \
        --reference current_defaults --trace benchmarks/results/archive/trace_reach_current_defaults.json \
        --out benchmarks/results/archive/episode_overlap_cpu_tcp_3000.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def overlap(rows: list[dict], reference: str) -> dict:
    """rows: ablation rows (name, per_episode_success) -> {"rows": [...], "per_episode": [...]} (see module doc).

    Rows without `per_episode_success` are skipped; every other row must have as many episodes as the
    reference."""
    by_name = {r["name"]: r for r in rows if r.get("per_episode_success")}  # a rerun row replaces the earlier one
    if reference not in by_name:
        raise ValueError(f"--reference {reference!r} is not a row with per_episode_success; rows: {sorted(by_name)}")
    ref = by_name[reference]["per_episode_success"]
    out_rows, solved_by = [], [0] * len(ref)
    for name, r in by_name.items():
        s = r["per_episode_success"]
        if len(s) != len(ref):
            raise ValueError(f"row {name!r} has {len(s)} episodes, the reference {len(ref)}")
        out_rows.append({
            "name": name, "successes": sum(s), "episodes": len(s),
            "shared_with_reference": sum(a and b for a, b in zip(ref, s)),
            "only_this_row": sum(b and not a for a, b in zip(ref, s)),
        })  # fmt: skip
        solved_by = [n + bool(b) for n, b in zip(solved_by, s)]
    per_episode = [{"episode": i, "rows_solving": n, "reference_solves": bool(ref[i])} for i, n in enumerate(solved_by)]
    return {"reference": reference, "n_rows": len(out_rows), "rows": out_rows, "per_episode": per_episode}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ablation", required=True, help="a run_ablation.py JSON")
    p.add_argument("--reference", default="current_defaults", help="the row the others are compared with")
    p.add_argument("--trace", help="a trace_rollouts.py JSON on the same seeds (adds each episode's goal)")
    p.add_argument("--out", help="write the result here as JSON")
    a = p.parse_args(argv)
    data = json.loads(Path(a.ablation).read_text())
    rows = data["rows"] if isinstance(data, dict) else data
    try:
        res = overlap(rows, a.reference)
    except ValueError as e:
        p.error(str(e))
    if a.trace:
        eps = json.loads(Path(a.trace).read_text())["episodes"]
        if len(eps) != len(res["per_episode"]):
            p.error(f"--trace has {len(eps)} episodes, the ablation rows {len(res['per_episode'])}")
        for e, t in zip(res["per_episode"], eps):
            e["seed"], e["goal"] = t["seed"], t["goal"]
    res["command"] = "python benchmarks/episode_overlap.py " + " ".join(sys.argv[1:] if argv is None else argv)
    print(f"| row | successes | shared with {a.reference} | only this row |")
    print("| --- | ---: | ---: | ---: |")
    for r in res["rows"]:
        print(f"| {r['name']} | {r['successes']}/{r['episodes']} | {r['shared_with_reference']} | {r['only_this_row']} |")
    print(f"\nrows solving each episode (of {res['n_rows']}):")
    for e in res["per_episode"]:
        goal = f"  goal {e['goal']}" if "goal" in e else ""
        print(f"  episode {e['episode']:2d}: {e['rows_solving']:2d}{' (reference)' if e['reference_solves'] else ''}{goal}")
    if a.out:
        Path(a.out).write_text(json.dumps(res, indent=1))
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
