"""benchmarks/episode_overlap.py: shared and row-only successes, checked on hand-made rows."""

import json

import pytest

import benchmarks.episode_overlap as eo

T, F = True, False


def _rows():
    return [
        {"name": "ref", "per_episode_success": [T, T, F, F]},
        {"name": "other", "per_episode_success": [T, F, T, F]},
        {"name": "smoke", "successes": 0},  # no per-episode record: skipped
        {"name": "other", "per_episode_success": [F, F, T, T]},  # a rerun replaces the earlier row
    ]


def test_counts_shared_and_row_only_successes_per_row_and_rows_per_episode():
    r = eo.overlap(_rows(), "ref")
    rows = {x["name"]: x for x in r["rows"]}
    assert r["n_rows"] == 2 and set(rows) == {"ref", "other"}
    assert rows["ref"] == {"name": "ref", "successes": 2, "episodes": 4, "shared_with_reference": 2,
                           "only_this_row": 0}
    assert rows["other"]["shared_with_reference"] == 0 and rows["other"]["only_this_row"] == 2
    assert [e["rows_solving"] for e in r["per_episode"]] == [1, 1, 1, 1]
    assert [e["reference_solves"] for e in r["per_episode"]] == [T, T, F, F]


def test_an_unknown_reference_or_a_row_on_other_episodes_is_refused():
    with pytest.raises(ValueError, match="'nope'"):
        eo.overlap(_rows(), "nope")
    with pytest.raises(ValueError, match="'short'"):
        eo.overlap(_rows() + [{"name": "short", "per_episode_success": [T]}], "ref")


def test_cli_adds_the_trace_goals_and_writes_json(tmp_path, capsys):
    ab = tmp_path / "ab.json"
    ab.write_text(json.dumps({"rows": _rows()}))
    trace = tmp_path / "trace.json"
    trace.write_text(json.dumps({"episodes": [{"seed": 100 + i, "goal": [0, 0, i]} for i in range(4)]}))
    out = tmp_path / "out.json"
    assert eo.main(["--ablation", str(ab), "--reference", "ref", "--trace", str(trace), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["per_episode"][3]["seed"] == 103 and res["per_episode"][3]["goal"] == [0, 0, 3]
    assert "| other | 2/4 | 0 | 2 |" in capsys.readouterr().out
