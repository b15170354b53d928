"""benchmarks/sampler_steps.py: a benchmark run's own lerobot-eval commands replayed per step count, checked
with a stand-in lerobot-eval that records its argv and writes an eval_info.json."""

import json
import stat
import sys

import pytest

import benchmarks.sampler_steps as ss

FAKE_EVAL = """#!{python}
import json, pathlib, sys
args = dict(a[2:].split("=", 1) for a in sys.argv[1:] if a.startswith("--") and "=" in a)
out = pathlib.Path(args["output_dir"]); out.mkdir(parents=True, exist_ok=True)
with open(pathlib.Path({calls!r}), "a") as f:
    f.write(json.dumps(sys.argv[1:]) + "\\n")
steps, seed = int(args["policy.num_inference_steps"]), int(args["seed"])
succ = [(seed + i) % 2 == 0 or steps == 4 for i in range(2)]  # 4 steps: both; 1 step: even seeds only
info = {{"overall": {{"eval_s": 10.0 * steps}}, "per_task": [{{"metrics": {{"successes": succ,
        "max_rewards": [1.0, 0.5]}}}}]}}
(out / "eval_info.json").write_text(json.dumps(info))
"""


def _run_json(tmp_path, status="done"):
    cmds = [["/old/venv/bin/lerobot-eval", "--policy.path=/ckpt", "--env.task=reach-v3", "--eval.n_episodes=2",
             f"--seed={seed}", f"--output_dir=/old/out/{seed}", "--policy.num_inference_steps=8"]
            for seed in (1000, 1002)]
    run = {"method": "rnd_ai", "task": "reach-v3", "status": status, "checkpoint": "/ckpt",
           "commands": {"train": [], "eval": cmds},
           "eval_chunks": {"2:4": {"successes": [True, False]}, "0:2": {"successes": [True, True]}}}
    p = tmp_path / "rnd_ai__reach-v3__n10__seed0.json"
    p.write_text(json.dumps(run))
    return p


def test_replayed_command_keeps_its_flags_and_replaces_output_and_step_count():
    argv = ["/old/lerobot-eval", "--policy.path=/c", "--seed=1000", "--output_dir=/o",
            "--policy.num_inference_steps=8", "--env.task=reach-v3"]
    assert ss.with_inference_steps(argv, 1, "/new", "/venv/lerobot-eval") == [
        "/venv/lerobot-eval", "--policy.path=/c", "--seed=1000", "--env.task=reach-v3", "--output_dir=/new",
        "--policy.num_inference_steps=1"]


def test_replays_each_chunk_per_step_count_resumes_and_keeps_the_committed_successes(tmp_path, capsys):
    calls = tmp_path / "calls.txt"
    fake = tmp_path / "lerobot-eval"
    fake.write_text(FAKE_EVAL.format(python=sys.executable, calls=str(calls)))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    out = tmp_path / "steps.json"
    args = ["--run-json", str(_run_json(tmp_path)), "--inference-steps", "4,1", "--out", str(out),
            "--lerobot-eval", str(fake), "--work-dir", str(tmp_path / "work")]
    assert ss.main(args) == 0
    res = json.loads(out.read_text())
    by = {e["num_inference_steps"]: e for e in res["entries"]}
    assert set(by) == {4, 1}
    # chunks in episode order (0:2 before 2:4), whatever the JSON order
    assert by[4]["committed_successes"] == [True, True, True, False]
    assert by[4]["per_episode_success"] == [True] * 4 and by[4]["successes"] == 4
    assert by[1]["per_episode_success"] == [True, False, True, False]  # seeds 1000, 1001, 1002, 1003
    assert by[1]["eval_s"] == 20.0 and by[4]["eval_s"] == 80.0  # two chunks each
    assert by[1]["test_seeds"] and by[1]["first_seed"] == 1000
    assert res["command"].startswith("python benchmarks/sampler_steps.py --run-json")
    first = [json.loads(line) for line in calls.read_text().splitlines()]
    assert len(first) == 4
    assert all(sum(a.startswith("--policy.num_inference_steps=") for a in c) == 1 for c in first)
    table = capsys.readouterr().out
    assert "| 1 | 2/4 |" in table and "| 0.25 | 2/4 |" in table  # time ratio and episodes shared with 4 steps
    assert ss.main(args) == 0  # resumed: nothing evaluated again
    assert len(calls.read_text().splitlines()) == 4 and len(json.loads(out.read_text())["entries"]) == 2


def test_an_unfinished_run_or_bad_step_counts_are_refused(tmp_path):
    with pytest.raises(SystemExit, match="not 'done'"):
        ss.main(["--run-json", str(_run_json(tmp_path, status="running")), "--out", str(tmp_path / "o.json")])
    with pytest.raises(SystemExit):
        ss.main(["--run-json", str(_run_json(tmp_path)), "--inference-steps", "4,0", "--out", str(tmp_path / "o.json")])


def test_benchmarks_md_section_says_which_seeds_and_whether_the_committed_run_reproduced():
    from benchmarks.write_benchmarks_md import sampler_steps_section

    def entry(steps, succ, committed, eval_s):
        return {"name": "run", "task": "reach-v3", "num_inference_steps": steps, "successes": sum(succ),
                "episodes": len(succ), "ci95": [0.1, 0.9], "eval_s": eval_s, "per_episode_success": succ,
                "test_seeds": True, "committed_successes": committed}

    res = {"command": "python benchmarks/sampler_steps.py ...", "what": "same checkpoints",
           "entries": [entry(4, [True, False], [True, False], 100.0), entry(1, [True, True], [True, False], 75.0)]}
    text = "\n".join(sampler_steps_section(res, "one_step_sampling_test.json"))
    assert "evaluation seeds" in text and "validation" not in text
    assert "| run | reach-v3 | 1 | 2/2 |" in text and "| 75 | 0.75 | 1/2 |" in text
    assert "1 of 1 checkpoints repeat" in text  # only the 4-step entry is compared with the committed run


def test_checkpoint_entries_get_stable_distinct_names(tmp_path):
    a, b = tmp_path / "run_a" / "pretrained_model", tmp_path / "run_b" / "pretrained_model"
    assert ss.checkpoint_name("reach-v3", str(a)) == ss.checkpoint_name("reach-v3", str(a))  # resume finds it
    assert ss.checkpoint_name("reach-v3", str(a)) != ss.checkpoint_name("reach-v3", str(b))
    assert ss.checkpoint_name("reach-v3", str(a)).startswith("reach-v3__")


def test_checkpoint_mode_evaluates_with_the_cameras_its_demos_were_recorded_with(tmp_path):
    """A checkpoint trained on corner2 + topview demos must not be evaluated with the env's default cameras."""
    data = tmp_path / "demos"
    (data / "meta").mkdir(parents=True)
    (data / "meta" / "rnd_recording.json").write_text(json.dumps(
        {"settings": {"suite": "metaworld", "cameras": ["corner2", "topview"]}}))
    ckpt = tmp_path / "pretrained_model"
    ckpt.mkdir()
    (ckpt / "train_config.json").write_text(json.dumps({"dataset": {"root": str(data)}}))
    a = ss.argparse.Namespace(run_json=[], checkpoint=[f"reach-v3={ckpt}"], seed=100, episodes=20)
    (target,) = ss.targets_from_args(a)
    assert "--env.camera_names=[corner2,topview]" in target["commands"][0]

    # the env's default cameras: no camera flag; the demos gone: refused rather than guessed
    (data / "meta" / "rnd_recording.json").write_text(json.dumps(
        {"settings": {"suite": "metaworld", "cameras": ["corner2", "behindGripper"]}}))
    (target,) = ss.targets_from_args(a)
    assert not any(x.startswith("--env.camera_names") for x in target["commands"][0])
    (data / "meta" / "rnd_recording.json").unlink()
    (data / "meta").rmdir()
    data.rmdir()
    with pytest.raises(SystemExit, match="dataset.root"):
        ss.targets_from_args(a)
