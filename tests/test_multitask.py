"""Several tasks in one dataset and one evaluation (issue 35): `lerobot-rnd-record --task a,b` and
`--env.type=rnd_mw --env.task=a,b` through LeRobot's own `make_env` and `eval_policy_all`.

References: the task strings are LeRobot's own MetaWorld descriptions (its `envs/metaworld_config.json`, read here
directly); the placements of each task are those a one-task recording with the same seed makes."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers import gl_available

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

TASKS = ("reach-v3", "drawer-close-v3")
SMALL = ["--image-size", "32", "--extra-steps", "2"]


def lerobot_descriptions() -> dict[str, str]:
    """LeRobot's MetaWorld task descriptions, from its own config file."""
    import lerobot

    path = Path(lerobot.__file__).parent / "envs" / "metaworld_config.json"
    return json.loads(path.read_text())["TASK_DESCRIPTIONS"]


def _record(root: Path, *flags: str) -> dict:
    from lerobot_rnd.sim import record as rec

    return rec.record(rec._parse(["--root", str(root), "--repo-id", f"local/{root.name}", *SMALL, *flags]),
                      progress=False)  # fmt: skip


def _episode_tasks(root: Path) -> list[str]:
    """Each episode's task strings, in episode order (LeRobot's meta/episodes)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(f"local/{root.name}", root=root)
    eps = sorted(meta.episodes.to_list(), key=lambda e: e["episode_index"])
    return [tuple(e["tasks"]) for e in eps]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """A two-task recording (one episode of each) and one-task recordings of each task with the same seed."""
    pytest.importorskip("metaworld")
    base = tmp_path_factory.mktemp("multitask")
    out = {"both": base / "both"}
    _record(out["both"], "--task", ",".join(TASKS), "--episodes", "1")
    for task in TASKS:
        out[task] = base / task
        _record(out[task], "--task", task, "--episodes", "1")
    return out


def _placements(root: Path, task: str) -> list[list[float]]:
    log = json.loads((root / "meta" / "rnd_recording.json").read_text())
    return [a["placement"] for a in log["attempts"] if a["success"] and a.get("task", task) == task]


def test_recorder_writes_each_task_with_lerobots_description_and_the_one_task_placements(recordings):
    desc = lerobot_descriptions()
    assert _episode_tasks(recordings["both"]) == [(desc[TASKS[0]],), (desc[TASKS[1]],)]
    for task in TASKS:
        assert _placements(recordings["both"], task) == _placements(recordings[task], task)
    log = json.loads((recordings["both"] / "meta" / "rnd_recording.json").read_text())
    assert [a["task"] for a in log["attempts"]] == list(TASKS)


def test_resume_adds_episodes_to_every_task(recordings, tmp_path):
    root = tmp_path / "both"
    shutil.copytree(recordings["both"], root)
    summary = _record(root, "--task", ",".join(TASKS), "--episodes", "2", "--resume")
    assert summary["episodes_per_task"] == dict.fromkeys(TASKS, 2) and summary["episodes"] == 4
    desc = lerobot_descriptions()
    assert _episode_tasks(root) == [(desc[TASKS[0]],), (desc[TASKS[1]],), (desc[TASKS[0]],), (desc[TASKS[1]],)]
    # the second episode of each task is the second placement of that task's one-task sequence
    log = json.loads((root / "meta" / "rnd_recording.json").read_text())
    for task in TASKS:
        mine = [a for a in log["attempts"] if a["task"] == task]
        assert [a["placement_index"] for a in mine] == list(range(len(mine)))
    again = _record(root, "--task", ",".join(TASKS), "--episodes", "2", "--resume")
    assert "nothing to record" in again["message"] and "per task" in again["message"]


def _env_cfg(task: str, **kw):
    from lerobot.envs.configs import EnvConfig

    return EnvConfig.get_choice_class("rnd_mw")(task=task, observation_height=32, observation_width=32, **kw)


def test_make_env_gives_one_group_per_task_and_each_env_its_task_string():
    pytest.importorskip("metaworld")
    from lerobot.envs.utils import add_envs_task
    from lerobot.scripts import lerobot_eval, lerobot_train

    import lerobot_policy_rnd  # noqa: F401  (what LeRobot's plugin discovery imports)

    desc = lerobot_descriptions()
    for make_env in (lerobot_eval.make_env, lerobot_train.make_env):  # the names lerobot-eval / -train call
        envs = make_env(_env_cfg(",".join(TASKS), episode_length=2), n_envs=2)
        assert list(envs) == list(TASKS) and all(list(g) == [0] for g in envs.values())
        for task, group in envs.items():
            obs, _ = group[0].reset(seed=[1000, 1001])
            assert add_envs_task(group[0], {"agent_pos": obs["agent_pos"]})["task"] == [desc[task]] * 2
            group[0].close()
    # one task: LeRobot's own path, and the policy now gets the task string too (it got "" before)
    (group,) = lerobot_eval.make_env(_env_cfg(TASKS[0]), n_envs=1).values()
    obs, _ = group[0].reset(seed=0)
    assert add_envs_task(group[0], {"agent_pos": obs["agent_pos"]})["task"] == [desc[TASKS[0]]]
    group[0].close()


@pytest.mark.parametrize(("task", "extra", "words"), [
    ("reach-v3,reach-v3", {}, ["reach-v3 more than once"]),
    ("reach-v3,reach-v9", {}, ["unknown task(s) reach-v9", "drawer-close-v3"]),
    ("reach-v3,drawer-close-v3", {"placements": [[0.0] * 6]}, ["--env.placements", "one at a time"]),
], ids=["repeated", "unknown", "placements-of-one-task"])  # fmt: skip
def test_bad_task_lists_are_refused_naming_the_fix(task, extra, words):
    from lerobot.envs.factory import make_env

    import lerobot_policy_rnd  # noqa: F401

    with pytest.raises(ValueError) as raised:
        make_env(_env_cfg(task, **extra))
    for word in words:
        assert word in str(raised.value), str(raised.value)


def test_other_env_types_reach_lerobots_make_env_unchanged():
    from lerobot.envs.configs import EnvConfig

    from lerobot_rnd.sim.multitask import multitask_make_env

    calls = []
    wrapped = multitask_make_env(lambda cfg, n_envs=1, use_async_envs=False, *a, **k: calls.append((cfg, n_envs)))
    cfg = EnvConfig.get_choice_class("pusht")()
    cfg.task = "a,b"  # a comma in another type's task is that type's business
    wrapped(cfg, 3)
    assert calls == [(cfg, 3)]
    assert multitask_make_env(wrapped) is wrapped  # installing twice wraps once


def test_lerobot_eval_loop_reports_each_task_and_the_policy_gets_each_tasks_string(recordings, monkeypatch):
    """LeRobot's `eval_policy_all` over `--env.task=a,b` with a task-conditioned R&D policy trained on the two-task
    dataset (untrained weights: this checks the plumbing, not success)."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.policies.factory import make_policy, make_pre_post_processors
    from lerobot.scripts.lerobot_eval import eval_policy_all, make_env

    import lerobot_policy_rnd  # noqa: F401
    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy
    from tests.helpers import TINY_POLICY_KWARGS

    root = recordings["both"]
    meta = LeRobotDatasetMetadata("local/both", root=root)
    cfg = RnDConfig(**TINY_POLICY_KWARGS)
    features = dataset_to_policy_features(meta.features)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    torch.manual_seed(0)
    policy = make_policy(cfg, ds_meta=meta)
    desc = lerobot_descriptions()
    assert policy.config.task_conditioning and sorted(policy.config.tasks) == sorted(desc[t] for t in TASKS)
    pre, post = make_pre_post_processors(cfg, dataset_stats=meta.stats)

    seen = []
    original = RnDPolicy._task_index

    def spy(self, batch, batch_size, device):
        seen.append(list(batch.get("task")))
        return original(self, batch, batch_size, device)

    monkeypatch.setattr(RnDPolicy, "_task_index", spy)
    env_cfg = _env_cfg(",".join(TASKS), episode_length=3)
    envs = make_env(env_cfg, n_envs=1)
    env_pre, env_post = make_env_pre_post_processors(env_cfg, cfg)
    try:
        info = eval_policy_all(envs, policy, env_pre, env_post, pre, post, n_episodes=1, start_seed=1000)
    finally:
        for group in envs.values():
            group[0].close()
    assert [e["task_group"] for e in info["per_task"]] == list(TASKS)
    assert set(info["per_group"]) == set(TASKS) and info["overall"]["n_episodes"] == 2
    assert all(len(e["metrics"]["successes"]) == 1 for e in info["per_task"])
    assert [s for s in seen if s] and {tuple(s) for s in seen} == {(desc[TASKS[0]],), (desc[TASKS[1]],)}
    assert np.isfinite(info["overall"]["avg_sum_reward"])


def test_tasks_seen_through_other_cameras_are_refused_for_one_dataset():
    """One dataset has one camera calibration: the recorder compares each task's cameras with the first task's."""
    pytest.importorskip("metaworld")
    from dataclasses import replace

    from lerobot_rnd.sim import record as rec
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv

    env = RnDMetaWorldEnv("reach-v3", observation_height=32, observation_width=32)
    try:
        emb = env.embodiment()
    finally:
        env.close()
    rec._check_same_cameras(emb, emb, "reach-v3", "drawer-close-v3")  # the same cameras pass
    key = "observation.images.corner2"
    T = np.array(emb.cameras[key].T_world_cam, dtype=float)
    T[0, 3] += 0.05  # corner2 5 cm further along x
    moved = emb._replace(cameras={**emb.cameras, key: replace(emb.cameras[key], T_world_cam=T)})
    with pytest.raises(rec.SettingError, match="reach-v3 and drawer-close-v3 have differently placed"):
        rec._check_same_cameras(emb, moved, "reach-v3", "drawer-close-v3")
