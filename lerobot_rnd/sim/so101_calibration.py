"""A calibration session on the simulated SO-101, recorded as a user records one on the real arm: a ChArUco board
lies still in front of the arm, the arm visits poses where the wrist camera sees the board, pausing at each, and
``lerobot-record``'s dataset layout holds the frames (``observation.state`` / ``action`` = the SO-101 joints).
``lerobot-rnd-calibrate solve --dataset <root> --robot so101 --wrist observation.images.wrist`` then measures the
cameras from it, as it would on a real arm (docs/SO101.md)::

    python -m lerobot_rnd.sim.so101_calibration --root outputs/data/so101_calib --image-size 256

writes the dataset and ``<root>/board.json`` (the board that lies in the scene).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lerobot_rnd.arrays import look_at
from lerobot_rnd.calibration.charuco import ChArUcoBoard
from lerobot_rnd.sim.so101_experts import ik_position_first, min_jerk
from lerobot_rnd.sim.so101_scene import (
    CALIBRATION_BOARD_POSE,
    WRIST_CAMERA_LOOKAT_EE,
    WRIST_CAMERA_POS_EE,
)

#: the board of a simulated session: 7x5 squares of 3 cm (about a sheet of A4)
SESSION_BOARD = ChArUcoBoard((7, 5), 0.03, 0.022)
MOVE_STEPS = 20  # frames between poses (moving: the calibration's still-frame filter skips them)
HOLD_STEPS = 8  # frames held at each pose


def session_joint_targets(n_poses: int, seed: int = 0, board: ChArUcoBoard = SESSION_BOARD) -> np.ndarray:
    """(n_poses, 6) LeRobot joint vectors whose wrist camera looks at the board from different sides and heights,
    aiming the camera as its nominal mount would (the measured calibration never sees the scene's true one)."""
    rng = np.random.default_rng(seed)
    w, h = board.size_m
    centre = (CALIBRATION_BOARD_POSE @ np.array([w / 2, h / 2, 0.0, 1.0]))[:3]
    T_ee_cam_nominal = look_at(WRIST_CAMERA_POS_EE, WRIST_CAMERA_LOOKAT_EE, up=(1.0, 0.0, 0.0))
    out, q = [], np.array([0.0, -40.0, 20.0, 80.0, 0.0, 40.0])
    for _ in range(n_poses):
        eye = centre + [rng.uniform(-0.1, 0.06), rng.uniform(-0.1, 0.1), rng.uniform(0.16, 0.28)]
        look = centre + rng.normal(size=3) * np.array([0.02, 0.02, 0.0])
        T_world_cam = look_at(eye, look, up=(1.0, 0.0, 0.0), roll=rng.uniform(-0.35, 0.35))
        q, _ = ik_position_first(T_world_cam @ np.linalg.inv(T_ee_cam_nominal), q)
        out.append(q.copy())
    return np.array(out)


def record_session(root: str | Path, n_poses: int = 30, image_size: int = 256, seed: int = 0,
                   repo_id: str = "local/so101_calibration") -> dict:  # fmt: skip
    """Records the session into a new LeRobot dataset at ``root`` (+ ``board.json``); returns a summary."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from tqdm import tqdm

    from lerobot_rnd.sim.record import dataset_features
    from lerobot_rnd.sim.so101_env import ACTION_NAMES, DEFAULT_CAMERAS, SO101_FPS, STATE_NAMES, RnDSO101Env
    from lerobot_rnd.sim.so101_scene import hide

    root = Path(root)
    if root.exists():
        raise FileExistsError(f"{root} exists: choose a new --root (a calibration session is recorded in one go)")
    env = RnDSO101Env("reach-target", observation_height=image_size, observation_width=image_size,
                      terminate_on_success=False, episode_length=10**6, calibration_board=SESSION_BOARD)  # fmt: skip
    features = dataset_features(DEFAULT_CAMERAS, (image_size, image_size), STATE_NAMES, ACTION_NAMES)
    ds = LeRobotDataset.create(repo_id=repo_id, fps=SO101_FPS, features=features, root=root,
                               robot_type="so101_follower", use_videos=False)  # fmt: skip
    obs, _ = env.reset(options={"placement": [0.2, 0.0, 0.5 * (0.03 + 0.16)]})
    hide(env.model, "target")  # no ball, nor its post, in a calibration session
    q = env.joints()
    frames = 0
    for target in tqdm(session_joint_targets(n_poses, seed), desc="calibration poses", leave=False):
        for a in np.concatenate([min_jerk(q, target, MOVE_STEPS), np.repeat(target[None], HOLD_STEPS, 0)]):
            ds.add_frame({**{f"observation.images.{c}": obs["pixels"][c] for c in DEFAULT_CAMERAS},
                          "observation.state": obs["agent_pos"], "action": a.astype(np.float32),
                          "task": "calibration"})  # fmt: skip
            obs, *_ = env.step(a)
            frames += 1
        q = target
    ds.save_episode()
    ds.finalize()
    env.close()
    SESSION_BOARD.save_json(root / "board.json")
    summary = {"root": str(root), "frames": frames, "poses": n_poses, "image_size": image_size, "board": str(root / "board.json")}
    return summary


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", required=True, type=Path)
    p.add_argument("--poses", type=int, default=30)
    p.add_argument("--image-size", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    try:
        print(json.dumps(record_session(a.root, a.poses, a.image_size, a.seed), indent=1))
    except FileExistsError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
