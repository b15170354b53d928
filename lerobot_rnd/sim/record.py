"""Record scripted-expert demonstrations of a MetaWorld or Panda task into a LeRobotDataset (v3, PNG images).

    python -m lerobot_rnd.sim.record --task reach-v3 --episodes 20 \\
        --root outputs/data/mw_reach --repo-id local/mw_reach [--placements random|fps] [--seed 0] \\
        [--fps-pool 1000] [--image-size 128] [--cameras corner2,behindGripper] [--resume]
    lerobot-rnd-record --suite panda --task lift-cube --episodes 20 \\
        --root outputs/data/panda_lift --repo-id local/panda_lift

Suites: ``metaworld`` (default; ``lerobot_rnd.sim.metaworld_env``, MetaWorld V3 tasks, 80 fps, 4-D
actions) and ``panda`` (``lerobot_rnd.sim.panda_env``: Franka Panda + Robotiq on gym-hil's assets, tasks
lift-cube / push-block / press-button, 10 fps, 7-D actions; default cameras front,wrist and
``--max-steps`` 120).

Only successful episodes are kept (failures are counted and reported). ``--episodes`` is the number of
kept episodes the dataset should hold: with ``--resume`` recording continues where it stopped, with the
next placements of the same deterministic sequence. Placements are MetaWorld ``rand_vec``s:
``random`` draws them uniformly from the task's range (seeded); ``fps`` picks them by furthest point
sampling over a seeded pool of ``--fps-pool`` valid candidates (any prefix is well spread).

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
import json
import logging
import shutil
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lerobot_rnd.embodiment import EMBODIMENT_FILE_IN_DATASET

logger = logging.getLogger(__name__)

RECORDING_FILE = "meta/rnd_recording.json"
SUITES = ("metaworld", "panda")
PANDA_DEFAULT_CAMERAS = ["front", "wrist"]
PANDA_DEFAULT_MAX_STEPS = 120


# --------------------------------------------------------------------------------------------------
# placements
# --------------------------------------------------------------------------------------------------
def furthest_point_order(points: np.ndarray, n: int, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Indices of ``n`` points chosen greedily furthest from those chosen so far (coordinates scaled
    to the placement range; the first is the point nearest the pool's centre)."""
    span = np.where(high - low > 0, high - low, 1.0)
    x = (points - low) / span
    first = int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))
    order = [first]
    d = np.linalg.norm(x - x[first], axis=1)
    for _ in range(min(n, len(x)) - 1):
        nxt = int(np.argmax(d))
        order.append(nxt)
        d = np.minimum(d, np.linalg.norm(x - x[nxt], axis=1))
    return np.asarray(order, dtype=np.int64)


class PlacementSequence:
    """Deterministic, indexable sequence of valid placements for one env (random or fps)."""

    def __init__(self, env, mode: str = "random", seed: int = 0, fps_pool: int = 1000):
        if mode not in ("random", "fps"):
            raise ValueError(f"placements must be 'random' or 'fps', got {mode!r}")
        self.env, self.mode, self.seed, self.fps_pool = env, mode, int(seed), int(fps_pool)
        self.rng = np.random.default_rng(self.seed)
        self._items: list[np.ndarray] = []
        if mode == "fps":
            pool = self._draw_valid(self.fps_pool)
            sp = env.placement_space
            order = furthest_point_order(np.stack(pool), len(pool), sp.low, sp.high)
            self._items = [pool[i] for i in order]

    def _draw_valid(self, n: int) -> list[np.ndarray]:
        out, tries = [], 0
        while len(out) < n:
            tries += 1
            if tries > 100 * n + 1000:
                raise RuntimeError(f"{self.env.task}: could not draw {n} valid placements")
            v = self.env.sample_placement(self.rng)
            if self.env.is_valid_placement(v):
                out.append(v)
        return out

    def __getitem__(self, i: int) -> np.ndarray:
        if self.mode == "fps":
            if i >= len(self._items):
                raise IndexError(f"placement {i} beyond the fps pool of {len(self._items)}: raise --fps-pool")
            return self._items[i]
        while len(self._items) <= i:
            self._items.extend(self._draw_valid(1))
        return self._items[i]


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


def record_metaworld(settings: RecordSettings, progress: bool = True) -> dict:
    """Record ``settings.episodes`` successful expert episodes of a MetaWorld task; returns a summary dict."""
    from lerobot_rnd.sim.metaworld_experts import MetaWorldExpert
    from lerobot_rnd.sim.metaworld_env import (
        LEROBOT_CORNER2_POS,
        MAX_PATH_LENGTH,
        METAWORLD_FPS,
        RnDMetaWorldEnv,
    )

    s = settings
    if s.suite != "metaworld":
        raise ValueError(f"record_metaworld needs suite 'metaworld', got {s.suite!r}")
    if s.max_steps + s.extra_steps > MAX_PATH_LENGTH:
        raise ValueError(f"max_steps + extra_steps must be <= {MAX_PATH_LENGTH}")
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
    expert = MetaWorldExpert(s.task, noise_std=s.noise_std, seed=s.seed)
    return _record(
        s, env, expert, fps=METAWORLD_FPS, robot_type="sawyer", action_names=None, progress=progress
    )


def record_panda(settings: RecordSettings, progress: bool = True) -> dict:
    """Record ``settings.episodes`` successful expert episodes of a Panda task
    (``lerobot_rnd.sim.panda_env``); returns a summary dict. ``cameras`` left at the MetaWorld default
    means the Panda default (front, wrist)."""
    from dataclasses import replace

    from lerobot_rnd.sim.panda_env import ACTION_NAMES, PANDA_TASKS, RnDPandaEnv
    from lerobot_rnd.sim.panda_experts import PandaExpert

    s = settings
    if s.suite != "panda":
        raise ValueError(f"record_panda needs suite 'panda', got {s.suite!r}")
    if s.task not in PANDA_TASKS:
        raise ValueError(f"unknown Panda task {s.task!r}; tasks: {', '.join(PANDA_TASKS)}")
    if s.cameras == RecordSettings().cameras:
        s = replace(s, cameras=list(PANDA_DEFAULT_CAMERAS))
    if s.flip_cameras:
        raise ValueError("--flip-cameras is not supported by the panda suite")
    env = RnDPandaEnv(
        s.task,
        camera_names=s.cameras,
        observation_height=s.image_size,
        observation_width=s.image_size,
        episode_length=s.max_steps + s.extra_steps,
        terminate_on_success=False,
    )
    expert = PandaExpert(s.task, noise_std=s.noise_std, seed=s.seed)
    return _record(
        s, env, expert, fps=env.metadata["render_fps"], robot_type="panda", action_names=ACTION_NAMES,
        progress=progress,
    )  # fmt: skip


def record(settings: RecordSettings, progress: bool = True) -> dict:
    """Record with the suite named in ``settings.suite`` ("metaworld" or "panda")."""
    if settings.suite == "metaworld":
        return record_metaworld(settings, progress=progress)
    if settings.suite == "panda":
        return record_panda(settings, progress=progress)
    raise ValueError(f"unknown suite {settings.suite!r}; suites: {', '.join(SUITES)}")


def _record(
    s: RecordSettings, env, expert, *, fps: int, robot_type: str, action_names, progress: bool
) -> dict:
    """The recording loop shared by the suites (``env`` / ``expert`` built from ``s``)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from tqdm import tqdm

    root = Path(s.root)
    record_keys = ("suite", "task", "cameras", "image_size", "flip_cameras", "lerobot_corner2_pos",
                   "state_layout", "placements", "seed", "fps_pool")  # fmt: skip
    key_defaults = {"suite": "metaworld"}  # recordings made before the key existed
    log: dict = {"settings": asdict(s), "attempts": []}
    if root.exists():
        if not s.resume:
            raise FileExistsError(
                f"{root} exists: pass --resume to add episodes to it, or choose another --root"
            )
        if not (root / "meta" / "info.json").exists():
            raise FileNotFoundError(f"{root} exists but holds no LeRobot dataset (meta/info.json missing)")
        dataset = LeRobotDataset(s.repo_id, root=root)
        rec_path = root / RECORDING_FILE
        if rec_path.exists():
            log = json.loads(rec_path.read_text())
            old = log["settings"]
            diff = {
                k: (old.get(k, key_defaults.get(k)), getattr(s, k))
                for k in record_keys
                if old.get(k, key_defaults.get(k)) != getattr(s, k)
            }
            if diff:
                raise ValueError(f"--resume with settings that differ from the recording's: {diff}")
            log["settings"] = asdict(s)
        expected = dataset_features(s.cameras, (s.image_size, s.image_size), env.state_names, action_names)
        for k, ft in expected.items():
            have = dataset.meta.features.get(k)
            if have is None or tuple(have["shape"]) != tuple(ft["shape"]):
                raise ValueError(f"--resume: dataset feature {k} is {have}, expected {ft}")
    else:
        dataset = LeRobotDataset.create(
            repo_id=s.repo_id,
            fps=fps,
            features=dataset_features(s.cameras, (s.image_size, s.image_size), env.state_names, action_names),
            root=root,
            robot_type=robot_type,
            use_videos=False,
        )
    env.embodiment().save_json(root / EMBODIMENT_FILE_IN_DATASET)
    if s.image_writer_threads > 0:
        dataset.start_image_writer(num_processes=0, num_threads=s.image_writer_threads)

    have = dataset.meta.total_episodes
    next_index = 1 + max((a["placement_index"] for a in log["attempts"]), default=-1)
    seq = PlacementSequence(env, s.placements, s.seed, s.fps_pool)
    max_attempts = s.max_attempts if s.max_attempts is not None else 3 * s.episodes + 10
    failures, attempts, frames_written, t0 = 0, 0, 0, time.time()
    bar = tqdm(total=s.episodes, initial=min(have, s.episodes), desc=f"{s.task} demos", disable=not progress)
    try:
        while have < s.episodes:
            if attempts >= max_attempts:
                raise RuntimeError(
                    f"gave up after {attempts} attempts ({failures} failures): the expert fails too often"
                )
            placement = seq[next_index]
            frames, ok, steps = run_expert_episode(env, expert, placement, s.max_steps, s.extra_steps)
            attempts += 1
            entry = {
                "placement_index": next_index,
                "placement": [float(v) for v in placement],
                "success": bool(ok),
                "steps_to_success": steps,
                "num_frames": len(frames) if ok else 0,
                "episode_index": have if ok else None,
            }
            next_index += 1
            if ok:
                for obs, action in frames:
                    frame = {f"observation.images.{c}": obs["pixels"][c] for c in s.cameras}
                    frame["observation.state"] = obs["agent_pos"].astype(np.float32)
                    frame["action"] = np.asarray(action, dtype=np.float32)
                    frame["task"] = env.task_description
                    dataset.add_frame(frame)
                dataset.save_episode()
                frames_written += len(frames)
                have += 1
                bar.update(1)
            else:
                failures += 1
                bar.set_postfix(failures=failures)
            log["attempts"].append(entry)
            (root / RECORDING_FILE).write_text(json.dumps(log, indent=1))
    finally:
        if dataset.image_writer is not None:
            dataset.stop_image_writer()
        dataset.finalize()
        bar.close()
        env.close()
        images = root / "images"  # LeRobot's temporary PNG folders (emptied once embedded in parquet)
        if images.is_dir() and not any(p.is_file() for p in images.rglob("*")):
            shutil.rmtree(images, ignore_errors=True)
    elapsed = time.time() - t0
    summary = {
        "root": str(root),
        "repo_id": s.repo_id,
        "episodes": have,
        "new_frames": frames_written,
        "attempts": attempts,
        "failures": failures,
        "seconds": round(elapsed, 2),
    }
    if frames_written:
        summary["frames_per_second"] = round(frames_written / max(elapsed, 1e-9), 1)
    return summary


def _parse(argv: Sequence[str] | None) -> RecordSettings:
    p = argparse.ArgumentParser(
        prog="python -m lerobot_rnd.sim.record",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    d = RecordSettings()
    p.add_argument("--suite", choices=list(SUITES), default=d.suite, help="metaworld (default) or panda")
    p.add_argument(
        "--task", default=None, help="task: MetaWorld V3 (default reach-v3) or Panda (default lift-cube)"
    )
    p.add_argument(
        "--episodes", type=int, default=d.episodes, help="successful episodes the dataset should hold"
    )
    p.add_argument("--root", required=True, help="dataset folder (must not exist unless --resume)")
    p.add_argument("--repo-id", required=True, help="dataset repo id, e.g. local/mw_reach")
    p.add_argument("--placements", choices=["random", "fps"], default=d.placements)
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
    p.add_argument("--max-attempts", type=int, default=None)
    p.add_argument("--resume", action="store_true", help="add episodes to an existing dataset")
    p.add_argument(
        "--image-writer-threads", type=int, default=d.image_writer_threads, help="PNG writer threads"
    )
    a = p.parse_args(argv)
    split = lambda x: [c for c in (t.strip() for t in x.split(",")) if c]
    panda = a.suite == "panda"
    task = a.task or ("lift-cube" if panda else d.task)
    cameras = split(a.cameras) if a.cameras else (list(PANDA_DEFAULT_CAMERAS) if panda else list(d.cameras))
    max_steps = a.max_steps
    if max_steps is None:
        max_steps = PANDA_DEFAULT_MAX_STEPS if panda else d.max_steps
    return RecordSettings(
        task=task, episodes=a.episodes, root=a.root, repo_id=a.repo_id, placements=a.placements, seed=a.seed,
        fps_pool=a.fps_pool, image_size=a.image_size, cameras=cameras, flip_cameras=split(a.flip_cameras),
        lerobot_corner2_pos=not a.metaworld_corner2_pos, state_layout=a.state_layout, max_steps=max_steps,
        extra_steps=a.extra_steps, noise_std=a.noise, max_attempts=a.max_attempts, resume=a.resume,
        image_writer_threads=a.image_writer_threads, suite=a.suite,
    )  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    settings = _parse(argv)
    summary = record(settings)
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
