"""benchmarks/validation_curve.py and the training-log parser it shares with the harness."""

from __future__ import annotations

import json
import subprocess

import pytest

import benchmarks.validation_curve as vc
from benchmarks.harness.reports import loss_curve_from_log


def _log_line(step: int, loss: float) -> str:
    # LeRobot's format: the step rounded to thousands above 999 (format_big_number, precision 0)
    shown = f"{step}" if step < 1000 else f"{step / 1000:.0f}K"
    return f"Training: 10%|# | {step}/9000 [00:10<01:00]INFO 2026 ot_train.py:435 step:{shown} smpl:1K ep:1 loss:{loss} grdn:1.0\n"


def test_loss_curve_counts_steps_that_lerobot_prints_rounded_to_thousands():
    text = "# 2026\n$ lerobot-train --steps=3000\n" + "".join(
        _log_line(s, s / 1e4) for s in range(50, 3001, 50)
    )
    curve = loss_curve_from_log(text, log_freq=50)
    assert [s for s, _ in curve] == list(range(50, 3001, 50))  # not 1000, 2000, 3000 only
    assert dict(curve)[1450] == pytest.approx(0.145) and dict(curve)[2550] == pytest.approx(0.255)


def test_loss_curve_restarts_its_count_at_each_invocation_and_keeps_the_last_loss():
    first = "$ lerobot-train\n" + "".join(_log_line(s, 1.0) for s in range(100, 701, 100))
    resumed = "$ lerobot-train --resume=true\n" + "".join(_log_line(s, 2.0) for s in range(600, 901, 100))
    curve = dict(loss_curve_from_log(first + resumed, log_freq=100))
    assert sorted(curve) == list(range(100, 901, 100))
    assert curve[500] == 1.0 and curve[600] == 2.0 and curve[900] == 2.0


def test_a_resumed_invocation_counts_from_the_step_it_resumed_at():
    # the Panda lift-cube 4-demo run: killed at step 1,950, resumed from checkpoint 1,500 of 3,000. LeRobot prints
    # 'step:2K' at 1,550, so anchoring on the printed value put the resumed losses at 2,000-3,450
    def lines(steps, total, loss):
        return "".join(f"Training:   3%|3         | {s - (3000 - total)}/{total} [00:10<01:00]INFO 2026 "
                       f"ot_train.py:435 step:{s if s < 1000 else f'{s / 1000:.0f}K'} smpl:1K loss:{loss}\n"
                       for s in steps)  # fmt: skip

    first = "$ lerobot-train --steps=3000\nINFO cfg.steps=3000 (3K)\n" + lines(range(50, 1951, 50), 3000, 1.0)
    resumed = "$ lerobot-train --resume=true\nINFO cfg.steps=3000 (3K)\nTraining:   0%|          | 0/1500 [00:00<?, ?step/s]" + lines(range(1550, 3001, 50), 1500, 2.0)
    curve = dict(loss_curve_from_log(first + resumed, log_freq=50))
    assert sorted(curve) == list(range(50, 3001, 50))
    assert curve[1500] == 1.0 and curve[1550] == 2.0 and curve[1950] == 2.0 and curve[3000] == 2.0


def _train_dir(tmp_path, steps=(1500, 3000)):
    train = tmp_path / "train"
    for s in steps:
        pm = train / "checkpoints" / f"{s:06d}" / "pretrained_model"
        pm.mkdir(parents=True)
        (pm / "train_config.json").write_text(
            json.dumps({"steps": 3000, "log_freq": 50, "policy": {"type": "rnd"}})
        )
    (tmp_path / "train.log").write_text(
        "$ lerobot-train\n" + "".join(_log_line(s, 1.0 / s) for s in range(50, 3001, 50))
    )
    return train


@pytest.fixture(autouse=True)
def _work_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setattr(vc, "WORK", tmp_path / "work")


def _fake_eval(calls, pattern):
    def run(cmd, **kwargs):
        calls.append(cmd)
        out = next(a.split("=", 1)[1] for a in cmd if a.startswith("--output_dir="))
        step = int(out.rsplit("_", 1)[1])
        from pathlib import Path

        Path(out).mkdir(parents=True)
        info = {"per_task": [{"metrics": {"successes": pattern[step]}}]}
        (Path(out) / "eval_info.json").write_text(json.dumps(info))
        return subprocess.CompletedProcess(cmd, 0)

    return run


def test_curve_evaluates_each_checkpoint_on_validation_seeds_and_resumes(tmp_path, monkeypatch):
    train = _train_dir(tmp_path)
    calls = []
    pattern = {1500: [True, False, False, False], 3000: [True, True, True, False]}
    monkeypatch.setattr(vc.subprocess, "run", _fake_eval(calls, pattern))
    out = tmp_path / "curve"
    argv = [
        "--train-dir",
        str(train),
        "--out",
        str(out),
        "--episodes",
        "4",
        "--eval-arg=--policy.num_inference_steps=2",
    ]
    assert vc.main(argv) == 0
    res = json.loads(out.with_suffix(".json").read_text())
    assert [(r["step"], r["successes"], r["episodes"]) for r in res["rows"]] == [(1500, 1, 4), (3000, 3, 4)]
    assert res["rows"][0]["training_loss_near_step"] == pytest.approx(1 / 1500)
    assert all("--seed=100" in c and "--policy.num_inference_steps=2" in c for c in calls)
    assert out.with_suffix(".png").exists()
    assert all("/work/curve/step_" in next(a for a in c if a.startswith("--output_dir=")) for c in calls)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "curve.json",
        "curve.png",
        "train",
        "train.log",
        "work",
    ]
    vc.main(argv)  # every checkpoint done: nothing is evaluated again
    assert len(calls) == 2
    vc.main([*argv, "--steps", "3000"])
    assert json.loads(out.with_suffix(".json").read_text())["commands"] == [
        "python benchmarks/validation_curve.py " + " ".join(argv),
        "python benchmarks/validation_curve.py " + " ".join([*argv, "--steps", "3000"]),
    ]


def test_curve_evaluates_with_the_cameras_of_the_training_demos(tmp_path, monkeypatch):
    """A run trained on demos recorded with MetaWorld's own corner2 pose is evaluated with it, not with the env's
    default pose (the policy would see a view it never saw)."""
    train = _train_dir(tmp_path)
    demos = tmp_path / "demos"
    (demos / "meta").mkdir(parents=True)
    (demos / "meta" / "rnd_recording.json").write_text(json.dumps(
        {"settings": {"suite": "metaworld", "cameras": ["corner2", "behindGripper"], "lerobot_corner2_pos": False}}))
    for cfg in train.glob("checkpoints/*/pretrained_model/train_config.json"):
        cfg.write_text(json.dumps({**json.loads(cfg.read_text()), "dataset": {"root": str(demos)}}))
    calls = []
    pattern = {1500: [True], 3000: [False]}
    monkeypatch.setattr(vc.subprocess, "run", _fake_eval(calls, pattern))
    assert vc.main(["--train-dir", str(train), "--out", str(tmp_path / "curve"), "--episodes", "1"]) == 0
    assert len(calls) == 2 and all("--env.use_lerobot_corner2_pos=false" in c for c in calls)


def test_curve_refuses_seeds_that_reach_the_evaluation_seeds(tmp_path):
    with pytest.raises(SystemExit):
        vc.main(["--train-dir", str(_train_dir(tmp_path)), "--out", str(tmp_path / "c"), "--val-seed", "990"])


def test_curve_names_the_missing_checkpoint(tmp_path, capsys):
    with pytest.raises(SystemExit):
        vc.main(["--train-dir", str(_train_dir(tmp_path)), "--out", str(tmp_path / "c"), "--steps", "4500"])
    assert "[4500] not saved" in capsys.readouterr().err


def test_curve_refuses_to_mix_two_runs_in_one_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(vc.subprocess, "run", _fake_eval([], {1500: [True], 3000: [False]}))
    out = str(tmp_path / "c")
    vc.main(["--train-dir", str(_train_dir(tmp_path)), "--out", out, "--episodes", "1"])
    other = tmp_path / "other"
    other.mkdir()
    with pytest.raises(SystemExit):
        vc.main(["--train-dir", str(_train_dir(other)), "--out", out, "--episodes", "1"])
    assert "another run's curve" in capsys.readouterr().err


def test_benchmarks_md_section_is_written_from_the_curve_json(tmp_path, monkeypatch):
    from benchmarks.write_benchmarks_md import validation_curve_section

    pattern = {1500: [False, False, False, True], 3000: [True, True, True, False]}
    monkeypatch.setattr(vc.subprocess, "run", _fake_eval([], pattern))
    out = tmp_path / "validation_curve_x"
    vc.main(
        [
            "--train-dir",
            str(_train_dir(tmp_path)),
            "--out",
            str(out),
            "--episodes",
            "4",
            "--steps",
            "3000,1500",
        ]
    )
    lines = validation_curve_section(
        json.loads(out.with_suffix(".json").read_text()), "validation_curve_x.json"
    )
    rows = [line for line in lines if line.startswith("| 1500 ") or line.startswith("| 3000 ")]
    assert [r.split(" | ")[1] for r in rows] == [
        "1/4 (25%)",
        "3/4 (75%)",
    ]  # ordered by step, whatever the order run
    assert rows[1].endswith(f"| {1 / 3000:.3f} |")
    assert "validation seeds 100-103" in "\n".join(lines)


def test_median_update_time_reads_lerobots_updt_s():
    from benchmarks.harness.reports import median_logged, median_update_s_from_log

    text = "step:50 loss:0.5 updt_s:0.300 data_s:0.01\nstep:100 loss:0.4 updt_s:0.900 data_s:0.05\n" \
           "step:150 loss:0.3 updt_s:0.320 data_s:0.02\n"  # fmt: skip
    assert median_update_s_from_log(text) == 0.32
    assert median_logged(text, "data_s") == 0.02  # the data-loading time is not mistaken for updt_s
    assert median_update_s_from_log("no timing logged") is None
