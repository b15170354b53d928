"""benchmarks/write_results_index.py: benchmarks/results/INDEX.md lists every result once and is up to date."""

from __future__ import annotations

import json
from collections import Counter

import pytest

import benchmarks.write_results_index as w


def test_every_result_is_listed_exactly_once():
    """Every JSON file and results folder under benchmarks/results (and archive/) appears once in INDEX.md."""
    listed = Counter(w.listed_entries((w.RESULTS / w.INDEX).read_text()))
    on_disk = set(w.find_entries(w.RESULTS))
    assert on_disk, "no results found"
    assert set(listed) == on_disk, (sorted(on_disk - set(listed)), sorted(set(listed) - on_disk))
    assert max(listed.values()) == 1, [k for k, n in listed.items() if n > 1]


def test_index_is_up_to_date():
    """Regenerating INDEX.md from the JSON gives the committed text (run benchmarks/write_results_index.py)."""
    assert w.build_index(w.RESULTS, w.STATUS) == (w.RESULTS / w.INDEX).read_text()
    assert w.main(["--check"]) == 0


def test_every_status_has_a_reason_and_archived_ones_live_in_the_archive():
    for name, (state, why) in w.STATUS.items():
        assert state in (w.CURRENT, w.ARCHIVED) and why.strip(), name
        where = w.RESULTS / (w.ARCHIVE + "/" + name if state == w.ARCHIVED else name)
        assert where.exists(), f"{name} is {state} but not at {where}"


def _results(tmp_path, names):
    for name in names:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"command": f"python make.py --out {name}", "code_commit": "abcdef0123"}))
    return tmp_path


def test_an_unclassified_result_is_refused(tmp_path):
    results = _results(tmp_path, ["a.json", "new.json"])
    with pytest.raises(ValueError, match="new.json: not in STATUS"):
        w.build_index(results, {"a.json": (w.CURRENT, "what a measures")})


def test_a_result_in_the_wrong_folder_or_missing_is_refused(tmp_path):
    results = _results(tmp_path, ["a.json", "archive/b.json"])
    status = {"a.json": (w.ARCHIVED, "superseded"), "b.json": (w.ARCHIVED, "old"), "gone.json": (w.CURRENT, "x")}
    with pytest.raises(ValueError) as err:
        w.build_index(results, status)
    assert "a.json: STATUS says archived, so it belongs at archive/a.json" in str(err.value)
    assert "gone.json: in STATUS but not on disk" in str(err.value)
    assert "b.json:" not in str(err.value)  # archived and in archive/: fine


def test_a_stale_index_fails_the_check(tmp_path, monkeypatch):
    results = _results(tmp_path, ["a.json", "archive/b.json", "run/results.json"])
    monkeypatch.setattr(w, "RESULTS", results)
    monkeypatch.setattr(w, "STATUS", {"a.json": (w.CURRENT, "what a measures"), "b.json": (w.ARCHIVED, "why b went"),
                                      "run": (w.CURRENT, "a run folder")})  # fmt: skip
    assert w.main(["--check"]) == 1  # no INDEX.md yet
    assert w.main([]) == 0
    text = (results / w.INDEX).read_text()
    assert w.listed_entries(text) == ["a.json", "run", "archive/b.json"]
    assert "python make.py --out a.json" in text and "`abcdef0`" in text and "Why archived: why b went" in text
    assert w.main(["--check"]) == 0
    (results / "archive" / "b.json").write_text(json.dumps({"command": "python other.py"}))
    assert w.main(["--check"]) == 1  # the JSON changed, INDEX.md did not


def test_current_results_name_config_files_that_exist():
    """A current result's config paths point at files in policies_config/ (a bench_train_step.py method SUITE/NAME
    once came out as policies_config/metaworld/SUITE/NAME.json)."""
    import re

    current = (w.RESULTS / w.INDEX).read_text().split("## Archived")[0]
    named = set(re.findall(r"policies_config/[\w/.-]+\.json", current))
    assert any("/so101/" in p for p in named), "expected the SO-101 configs among the current results"
    missing = sorted(p for p in named if not (w.REPO / p).exists())
    assert not missing, missing


def test_a_report_joined_from_several_calls_lists_every_call_oldest_first(tmp_path):
    folder = tmp_path / "spatial"
    folder.mkdir()
    bench = {"earlier_commands": ["/v/bin/python run_benchmark.py --tasks a,b", "/v/bin/python3.11 run_benchmark.py --tasks b"],
             "command": "/v/bin/python run_benchmark.py --tasks b --demos 4"}  # fmt: skip
    (folder / "results.json").write_text(json.dumps({"benchmark": bench}))
    assert w.commands_of(folder) == ["python run_benchmark.py --tasks a,b", "python run_benchmark.py --tasks b",
                                     "python run_benchmark.py --tasks b --demos 4"]  # fmt: skip
