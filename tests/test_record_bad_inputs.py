"""The recorder (``lerobot_rnd.sim.record``) under bad input: one test per row of docs/FAILURES.md, "Recorder".

Bad flags and dataset folders stop it with one line ``error: ...`` (exit code 2) that names the flag and
the fix, before anything is written. A stopped recording resumes to the episodes asked for: the SIGKILL
rows resume copies of the dataset folder taken at the moment of the kill (what the killed process would
have left on disk), while the recording runs in-process.
"""

import json
import os
import shutil
import subprocess
import sys

import pytest

from lerobot_rnd.sim import record as rec
from tests.helpers import REPO_ROOT, gl_available

needs_gl = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

REPO_ID = "local/rec_bad"
#: tiny episodes: 32 px images, reach-v3 succeeds in about 50 steps
SMALL = ["--image-size", "32", "--max-steps", "100", "--extra-steps", "2"]


def cli(root, *args) -> list[str]:
    return ["--root", str(root), "--repo-id", REPO_ID, *SMALL, *args]


def folder_state(root) -> dict:
    """Every path under ``root`` with its size and modification time (to show nothing was written)."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


# --------------------------------------------------------------------------------------------------
# flags and folders (no simulator needed)
# --------------------------------------------------------------------------------------------------
# id: (flags, root exists beforehand, exception, words of the message)
FLAG_ERRORS = {
    "unknown-task": (
        ["--task", "reach-v9"], False, ValueError, ["--task reach-v9", "did you mean reach-v3", "--list-tasks"]
    ),
    "unknown-panda-task": (
        ["--suite", "panda", "--task", "lift-cub"], False, ValueError,
        ["--task lift-cub", "did you mean lift-cube", "lift-cube, push-block, press-button, pick-place, slide-block"],
    ),
    "panda-task-without-suite-panda": (
        ["--task", "lift-cube"], False, ValueError, ["--task lift-cube is a Panda task", "add --suite panda"]
    ),
    "metaworld-task-with-suite-panda": (
        ["--suite", "panda", "--task", "reach-v3"], False, ValueError,
        ["--task reach-v3 is a MetaWorld V3 task", "drop --suite panda"],
    ),
    "repeated-task": (
        ["--task", "reach-v3,drawer-close-v3,reach-v3"], False, ValueError,
        ["--task names reach-v3 more than once", "list each task once"],
    ),
    "one-unknown-task-of-several": (
        ["--task", "reach-v3,drawer-clos-v3"], False, ValueError,
        ["--task drawer-clos-v3", "did you mean drawer-close-v3"],
    ),
    "episodes-zero": (["--episodes", "0"], False, ValueError, ["--episodes", "must be >= 1, got 0"]),
    "episode-longer-than-metaworld-allows": (
        ["--max-steps", "495", "--extra-steps", "10"], False, ValueError,
        ["--max-steps + --extra-steps must be <= 500"],
    ),
    "root-exists-without-resume": ([], True, FileExistsError, ["exists", "pass --resume", "another --root"]),
    "resume-into-a-folder-without-dataset": (
        ["--resume"], True, FileNotFoundError, ["holds no LeRobot dataset", "meta/info.json", "another --root"]
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", list(FLAG_ERRORS), ids=list(FLAG_ERRORS))
def test_bad_flags_stop_with_one_line_before_writing(tmp_path, capsys, case):
    flags, make_root, exc, words = FLAG_ERRORS[case]
    root = tmp_path / "ds"
    if make_root:
        root.mkdir()
    argv = cli(root, *flags)
    with pytest.raises(exc) as raised:
        rec.record(rec._parse(argv), progress=False)
    assert isinstance(raised.value, rec.RecordUsageError)
    assert rec.main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    for word in words:
        assert word in line, line
    assert list(tmp_path.iterdir()) == ([root] if make_root else []) and not any(root.glob("*"))


def test_cli_error_is_one_line_on_stderr_with_exit_code_2(tmp_path):
    """The real command line: no traceback, nothing else on stderr."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run(
        [sys.executable, "-m", "lerobot_rnd.sim.record", *cli(tmp_path / "ds", "--task", "reach-v9")],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300, check=False,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    expected = (
        "error: --task reach-v9 is not a MetaWorld V3 task; did you mean reach-v3 or reach-wall-v3? "
        "all tasks: lerobot-rnd-record --list-tasks"
    )
    assert r.stderr.splitlines() == [expected]
    assert not (tmp_path / "ds").exists()


@pytest.mark.parametrize("error", [RuntimeError, ValueError], ids=["RuntimeError", "ValueError"])
def test_unexpected_errors_keep_their_traceback(tmp_path, monkeypatch, error):
    """Only the recorder's own checks become one line: any other exception (even a ValueError) propagates."""

    def broken_env(settings):
        raise error("simulated bug")

    monkeypatch.setattr(rec, "_metaworld_env", broken_env)
    with pytest.raises(error, match="simulated bug"):
        rec.main(cli(tmp_path / "ds", "--task", "reach-v3"))


def test_list_tasks(capsys):
    assert rec.main(["--list-tasks"]) == 0
    out = capsys.readouterr().out
    assert "reach-v3" in out.split() and "button-press-topdown-wall-v3" in out.split() and "lift-cube" in out


# --------------------------------------------------------------------------------------------------
# one recording of reach-v3, stopped in four ways
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """A recording of 3 reach-v3 episodes stopped by a KeyboardInterrupt from the expert in episode 3
    (folder ``interrupted``: 2 episodes, the recorder's cleanup ran), and copies of its folder taken where a
    SIGKILL would have left it: ``killed-saving-episode-1`` / ``-2`` (inside LeRobot's save_episode, after it
    wrote meta/info.json, with the episode's data file still open) and ``killed-in-episode-3`` (while the
    expert ran episode 3)."""
    pytest.importorskip("metaworld")
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    from lerobot_rnd.sim.metaworld_experts import MetaWorldExpert

    base = tmp_path_factory.mktemp("stopped")
    root = base / "interrupted"
    saved = []
    meta_save, act = LeRobotDatasetMetadata.save_episode, MetaWorldExpert.act

    def save_episode(self, *args, **kwargs):
        meta_save(self, *args, **kwargs)
        saved.append(True)
        shutil.copytree(root, base / f"killed-saving-episode-{len(saved)}")

    def act_until_episode_3(self, env):
        if len(saved) == 2:
            shutil.copytree(root, base / "killed-in-episode-3")
            raise KeyboardInterrupt
        return act(self, env)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(LeRobotDatasetMetadata, "save_episode", save_episode)
        mp.setattr(MetaWorldExpert, "act", act_until_episode_3)
        with pytest.raises(KeyboardInterrupt):
            rec.main(cli(root, "--task", "reach-v3", "--episodes", "3"))
    return base


@pytest.fixture
def two_episodes(stopped, tmp_path):
    """A copy of a 2-episode reach-v3 dataset (32 px, cameras corner2,behindGripper) with its recording log."""
    root = tmp_path / "two"
    shutil.copytree(stopped / "interrupted", root)
    return root


# id: (flags, remove meta/rnd_recording.json, words of the message)
RESUME_MISMATCHES = {
    "other-task": (["--task", "push-v3"], False, ["--task reach-v3 (not push-v3)"]),
    "other-image-size": (["--image-size", "64"], False, ["--image-size 32 (not 64)"]),
    "other-cameras": (["--cameras", "corner2"], False, ["--cameras corner2,behindGripper (not corner2)"]),
    "other-expert": (["--expert-reach-target", "hand"], False, ["--expert-reach-target tcp (not hand)"]),
    "other-suite": (
        ["--suite", "panda", "--task", "lift-cube"], False,
        ["--suite metaworld (not panda)", "--task reach-v3 (not lift-cube)", "--cameras corner2,behindGripper (not front,wrist)"],
    ),
    "other-image-size-without-log": (
        ["--image-size", "64"], True, ["(32, 32, 3)", "(64, 64, 3)", "pass the recording's --image-size"]
    ),
    "other-cameras-without-log": (
        ["--cameras", "corner2,corner3"], True,
        ["has cameras behindGripper,corner2, not corner2,corner3", "pass --cameras behindGripper,corner2"],
    ),
}  # fmt: skip


@needs_gl
@pytest.mark.parametrize("case", list(RESUME_MISMATCHES), ids=list(RESUME_MISMATCHES))
def test_resume_with_other_settings_names_them(two_episodes, capsys, case):
    flags, without_log, words = RESUME_MISMATCHES[case]
    if without_log:
        (two_episodes / rec.RECORDING_FILE).unlink()
    before = folder_state(two_episodes)
    argv = cli(two_episodes, "--task", "reach-v3", "--episodes", "3", "--resume", *flags)
    with pytest.raises(ValueError):
        rec.record(rec._parse(argv), progress=False)
    assert rec.main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    for word in ["--resume:", "another --root", *words]:
        assert word in line, line
    assert folder_state(two_episodes) == before


@needs_gl
def test_resume_of_a_recording_older_than_the_expert_fix_names_its_expert(two_episodes, capsys):
    """A log written before `expert_reach_target` existed was recorded by MetaWorld's own policy ("hand")."""
    log_path = two_episodes / rec.RECORDING_FILE
    log = json.loads(log_path.read_text())
    del log["settings"]["expert_reach_target"]
    log_path.write_text(json.dumps(log))
    before = folder_state(two_episodes)
    assert rec.main(cli(two_episodes, "--task", "reach-v3", "--episodes", "3", "--resume")) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--expert-reach-target hand (not tcp)" in line, line
    assert folder_state(two_episodes) == before


@needs_gl
def test_resume_whose_placement_sequence_changed_is_refused(two_episodes, capsys):
    """A dataset begun with another placement sequence (as the Panda fps-centre ones recorded before the yaw
    symmetry) must not be extended with the new one: its demos would mix two sequences."""
    log_path = two_episodes / rec.RECORDING_FILE
    log = json.loads(log_path.read_text())
    log["attempts"][0]["placement"] = [v + 0.01 for v in log["attempts"][0]["placement"]]
    log_path.write_text(json.dumps(log))
    before = folder_state(two_episodes)
    assert rec.main(cli(two_episodes, "--task", "reach-v3", "--episodes", "3", "--resume")) == 2
    line = one_error_line(capsys.readouterr().err)
    for word in ["--resume:", "attempt 0 was recorded at placement", "placement sequence changed", "another --root"]:
        assert word in line, line
    assert folder_state(two_episodes) == before


@needs_gl
def test_resume_with_episodes_below_the_total_records_nothing(two_episodes, capsys):
    before = folder_state(two_episodes)
    assert rec.main(cli(two_episodes, "--task", "reach-v3", "--episodes", "1", "--resume")) == 0
    out, err = capsys.readouterr()
    message = (
        f"{two_episodes} already holds 2 episodes; --episodes is the total number wanted; nothing to record"
    )
    assert message in err
    summary = json.loads(out)
    assert summary["episodes"] == 2 and summary["new_frames"] == 0
    assert folder_state(two_episodes) == before


# id: (folder, loadable before the resume: episodes or None, --episodes of the resume)
STOPS = {
    "keyboardinterrupt-in-episode-3": ("interrupted", 2, 3),
    "sigkill-in-episode-3": ("killed-in-episode-3", 2, 3),
    "sigkill-while-saving-episode-2": ("killed-saving-episode-2", None, 3),
    "sigkill-while-saving-episode-1": ("killed-saving-episode-1", None, 1),
}


@needs_gl
@pytest.mark.parametrize("case", list(STOPS), ids=list(STOPS))
def test_resume_after_a_stop_keeps_only_whole_episodes(stopped, tmp_path, case):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    folder, loadable, episodes = STOPS[case]
    root = tmp_path / folder
    shutil.copytree(stopped / folder, root)
    if loadable is not None:  # the stop left a dataset of the saved episodes, without resume
        assert LeRobotDataset(REPO_ID, root=root).num_episodes == loadable
    assert rec.main(cli(root, "--task", "reach-v3", "--episodes", str(episodes), "--resume")) == 0

    ds = LeRobotDataset(REPO_ID, root=root)
    assert ds.num_episodes == episodes
    eps = ds.meta.episodes
    assert list(eps["episode_index"]) == list(range(episodes))
    ends = list(eps["dataset_to_index"])
    assert list(eps["dataset_from_index"]) == [0, *ends[:-1]] and ends[-1] == ds.num_frames
    assert [int(i) for i in ds.hf_dataset["index"]] == list(range(ds.num_frames))
    lengths = [b - a for a, b in zip([0, *ends[:-1]], ends, strict=True)]
    per_frame = [e for e, n in enumerate(lengths) for _ in range(n)]
    assert [int(i) for i in ds.hf_dataset["episode_index"]] == per_frame
    stats = json.loads((root / "meta" / "stats.json").read_text())
    assert stats["action"]["count"] == [ds.num_frames]  # the lost episode is not in the statistics
    assert ds[ds.num_frames - 1]["observation.images.corner2"].shape == (3, 32, 32)
    assert not (root / "images").exists()
    # the lost episode was recorded again from its placement: the placements of an uninterrupted run
    attempts = json.loads((root / rec.RECORDING_FILE).read_text())["attempts"]
    assert [(a["placement_index"], a["episode_index"]) for a in attempts] == [(i, i) for i in range(episodes)]
