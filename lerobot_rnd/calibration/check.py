"""``lerobot-rnd-check-calibration``: is a dataset's calibration right? Draws the gripper where the embodiment
says it is in the dataset's own frames, and scores how well the drawn outline sits on edges of the image.

    lerobot-rnd-check-calibration --dataset ~/.cache/huggingface/lerobot/me/so101_pick

Score per camera: the median distance (pixels) from the outline of the drawn gripper to the nearest edge the
image shows (OpenCV Canny), over frames where the gripper is in view. Right calibrations put the outline on the
real gripper's edges. To tell a right calibration from one that is merely near clutter, the same score is taken
with the camera moved by ``shift_m`` along and turned by ``turn_deg`` about each of its axes: when one of these
moves fits the images clearly better, the recorded calibration is flagged and the move is named. The grid image
shows the outlines over the frames, so a person sees at once what the numbers say.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from lerobot_rnd.camera_calibration import CameraCalibration
from lerobot_rnd.embodiment import EMBODIMENT_FILE_IN_DATASET, Embodiment, load_embodiment
from lerobot_rnd.geometry import invert_transform

OPEN_CLOSURE = 0.25  # frames whose gripper closure (0 open .. 1 closed) is at most this count as open
MIN_OUTLINE_PX = 20  # frames where the drawn outline has fewer pixels in the image are not scored
CHECK_IMAGE_IN_DATASET = "meta/rnd_calibration_check.png"


@dataclass
class CameraCheck:
    """One camera's result: ``score_px`` (median outline-to-edge distance, mean over ``frames_scored``), the best
    of the moved calibrations (``best_move``, ``best_move_score_px``), and ``flagged`` with its ``reason``."""

    key: str
    score_px: float
    frames_scored: int
    move_scores_px: dict[str, float] = field(default_factory=dict)
    best_move: str = ""
    best_move_score_px: float = float("nan")
    flagged: bool = False
    reason: str = ""


def moved_camera(cam: CameraCalibration, shift_cam: Sequence[float], rotvec_cam: Sequence[float]) -> CameraCalibration:
    """``cam`` moved by ``shift_cam`` (metres) and turned by ``rotvec_cam`` (radians), both in its own frame."""
    from scipy.spatial.transform import Rotation

    delta = np.eye(4)
    delta[:3, :3] = Rotation.from_rotvec(rotvec_cam).as_matrix()
    delta[:3, 3] = shift_cam
    if cam.T_world_cam is not None:
        return CameraCalibration(cam.name, cam.K, cam.image_size, T_world_cam=cam.T_world_cam @ delta)
    return CameraCalibration(cam.name, cam.K, cam.image_size, T_ee_cam=cam.T_ee_cam @ delta,
                             ee_follow_rotation=cam.ee_follow_rotation)  # fmt: skip


def camera_moves(shift_m: float, turn_deg: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """12 moves: +-``shift_m`` along and +-``turn_deg`` about the camera's x, y and z axes."""
    moves = {}
    for i, axis in enumerate("xyz"):
        for sign, s in ((1, "+"), (-1, "-")):
            e = np.zeros(3)
            e[i] = sign
            moves[f"shift {s}{shift_m * 100:g} cm along camera {axis}"] = (e * shift_m, np.zeros(3))
            moves[f"turn {s}{turn_deg:g} deg about camera {axis}"] = (np.zeros(3), e * math.radians(turn_deg))
    return moves


def gripper_masks(emb: Embodiment, key: str, states: torch.Tensor, cam: CameraCalibration | None = None) -> np.ndarray:
    """(N, H, W) bool: where the embodiment draws the gripper in camera ``key`` at each state (N, D)."""
    from lerobot_rnd.rendering import render

    cam = emb.cameras[key] if cam is None else cam
    T_world_ee = emb.ee_pose_source.ee_pose(states.to(torch.float64))
    T_cam_ee = invert_transform(cam.T_world_cam_at(T_world_ee)) @ T_world_ee
    N = states.shape[0]
    out = render(emb.mesh_batch(), torch.full((N,), emb.mesh_index(key), dtype=torch.long), T_cam_ee.float(),
                 cam.K_tensor()[None].expand(N, 3, 3), cam.image_size)  # fmt: skip
    return out.mask.numpy().astype(bool)


def edge_distance(image: np.ndarray) -> np.ndarray:
    """(H, W) float32: distance (pixels) from each pixel to the nearest Canny edge of ``image`` (H, W, 3) uint8."""
    grey = cv2.GaussianBlur(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), (3, 3), 0)
    med = float(np.median(grey))
    edges = cv2.Canny(grey, max(10.0, 0.66 * med), max(30.0, min(255.0, 1.33 * med)))
    return cv2.distanceTransform((edges == 0).astype(np.uint8), cv2.DIST_L2, 3)


def outline(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of ``mask`` that touch a pixel outside it inside the image (where the gripper leaves
    the image there is no edge to find)."""
    eroded = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return mask & (eroded == 0)


def outline_score(masks: np.ndarray, distances: np.ndarray) -> tuple[float, int]:
    """Mean over frames of the median edge distance along the outline, and the number of frames scored."""
    per_frame = []
    for m, d in zip(masks, distances):
        o = outline(m)
        if o.sum() >= MIN_OUTLINE_PX:
            per_frame.append(float(np.median(d[o])))
    return (float(np.mean(per_frame)) if per_frame else float("nan")), len(per_frame)


def check_cameras(
    emb: Embodiment,
    states: torch.Tensor,
    images: Mapping[str, np.ndarray],
    shift_m: float = 0.02,
    turn_deg: float = 2.0,
    margin_px: float = 0.3,
) -> dict[str, CameraCheck]:
    """Checks every camera in ``images`` (key -> (N, H, W, 3) uint8, the frames of ``states`` (N, D)).

    Flagged when a moved camera scores more than ``margin_px`` better (lower) than the recorded one, or when no frame
    shows the gripper."""
    results = {}
    moves = camera_moves(shift_m, turn_deg)
    for key, imgs in images.items():
        cam = emb.cameras[key]
        if tuple(imgs.shape[1:3]) != tuple(cam.image_size):
            cam = cam.resized(*imgs.shape[1:3])
        dist = np.stack([edge_distance(im) for im in imgs])
        score, n = outline_score(gripper_masks(emb, key, states, cam), dist)
        res = CameraCheck(key, score, n)
        if n == 0:
            res.flagged, res.reason = True, "the gripper is drawn outside the image in every frame checked"
            results[key] = res
            continue
        for name, (shift, rot) in moves.items():
            res.move_scores_px[name] = outline_score(gripper_masks(emb, key, states, moved_camera(cam, shift, rot)), dist)[0]
        res.best_move = min(res.move_scores_px, key=lambda k: np.nan_to_num(res.move_scores_px[k], nan=np.inf))
        res.best_move_score_px = res.move_scores_px[res.best_move]
        if res.best_move_score_px < score - margin_px:
            res.flagged = True
            res.reason = (f"the outline fits the image edges better after a {res.best_move} "
                          f"({res.best_move_score_px:.2f} px against {score:.2f} px)")  # fmt: skip
        results[key] = res
    return results


def overlay_grid(
    emb: Embodiment, states: torch.Tensor, images: Mapping[str, np.ndarray], checks: Mapping[str, CameraCheck],
    rows: int = 6, tile_height: int = 240,
) -> np.ndarray:
    """RGB grid (frames x cameras): each frame with the drawn gripper tinted green and outlined, a caption per column."""
    keys = list(images)
    N = states.shape[0]
    pick = np.unique(np.linspace(0, N - 1, min(rows, N)).round().astype(int))
    columns = []
    for key in keys:
        imgs = images[key]
        cam = emb.cameras[key]
        if tuple(imgs.shape[1:3]) != tuple(cam.image_size):
            cam = cam.resized(*imgs.shape[1:3])
        masks = gripper_masks(emb, key, states[pick], cam)
        tiles = []
        for im, m in zip(imgs[pick], masks):
            t = im.copy()
            t[m] = (0.6 * t[m] + 0.4 * np.array([0, 255, 0])).astype(np.uint8)
            t[outline(m)] = (0, 255, 0)
            scale = tile_height / t.shape[0]
            tiles.append(cv2.resize(t, (round(t.shape[1] * scale), tile_height), interpolation=cv2.INTER_NEAREST))
        col = np.concatenate(tiles, axis=0)
        c = checks.get(key)
        head = np.full((40, col.shape[1], 3), 255, np.uint8)
        text = key.removeprefix("observation.images.")
        if c is not None:
            text += f": {c.score_px:.2f} px" + ("  FLAGGED" if c.flagged else "")
        cv2.putText(head, text, (6, 27), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (200, 0, 0) if c and c.flagged else (0, 0, 0), 1,
                    cv2.LINE_AA)  # fmt: skip
        columns.append(np.concatenate([head, col], axis=0))
    return np.concatenate(columns, axis=1)


# ---------------------------------------------------------------------- the command
def dataset_frames(root: Path, n_frames: int, emb: Embodiment | None = None) -> tuple[torch.Tensor, dict[str, np.ndarray], int]:
    """States (N, D) and RGB frames per camera key (N, H, W, 3) uint8 of ``n_frames`` frames spread over the dataset,
    taken among the frames where the gripper is open when ``emb`` reads a gripper state (the meshes are drawn open:
    closed jaws would not match them). Also returns how many frames were candidates."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(f"local/{root.name}", root=root, video_backend="pyav")
    candidates = np.arange(len(ds))
    if emb is not None and emb.ee_pose_source.gripper_index is not None:
        all_states = torch.stack([torch.as_tensor(s) for s in ds.hf_dataset["observation.state"]])
        closure = emb.ee_pose_source.gripper(all_states).numpy()
        # open: below OPEN_CLOSURE, or (a dataset that never opens fully) the more open half of its frames
        candidates = np.flatnonzero(closure <= max(OPEN_CLOSURE, float(np.quantile(closure, 0.5))))
    pick = candidates[np.unique(np.linspace(0, len(candidates) - 1, min(n_frames, len(candidates))).round().astype(int))]
    states, images = [], {k: [] for k in ds.meta.camera_keys}
    for i in pick:
        item = ds[int(i)]
        states.append(torch.as_tensor(item["observation.state"]))
        for k, frames in images.items():
            img = item[k].permute(1, 2, 0).numpy()
            frames.append((img * 255.0 + 0.5).clip(0, 255).astype(np.uint8))
    return torch.stack(states), {k: np.stack(v) for k, v in images.items()}, len(candidates)


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="lerobot-rnd-check-calibration", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--dataset", type=Path, required=True, help="LeRobot dataset root")
    p.add_argument("--embodiment", default=None, help=f"embodiment JSON or preset (default <dataset>/{EMBODIMENT_FILE_IN_DATASET})")
    p.add_argument("--frames", type=int, default=12, help="frames spread over the dataset to check (default 12)")
    p.add_argument("--shift-cm", type=float, default=2.0, help="camera moves tried: this far along each axis")
    p.add_argument("--turn-deg", type=float, default=2.0, help="camera moves tried: this much about each axis")
    p.add_argument("--out", type=Path, default=None, help=f"grid image (default <dataset>/{CHECK_IMAGE_IN_DATASET}); a JSON beside it")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """0: every camera passes; 1: some camera is flagged; 2: bad flag or input (one ``error:`` line)."""
    a = _parse(argv)
    if not (a.dataset / "meta" / "info.json").is_file():
        print(f"error: --dataset {a.dataset}: not a LeRobot dataset (no meta/info.json)", file=sys.stderr)
        return 2
    source = a.embodiment or a.dataset
    try:
        emb = load_embodiment(source)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: embodiment {source}: {e} (run lerobot-rnd-calibrate, or pass --embodiment)", file=sys.stderr)
        return 2
    states, images, n_open = dataset_frames(a.dataset, a.frames, emb)
    print(f"checking {len(states)} frames spread over the {n_open} frames with the gripper open (or most open)")
    missing = [k for k in images if k not in emb.cameras]
    if missing:
        print(f"error: the embodiment has no calibration for {missing} (it has {sorted(emb.cameras)})", file=sys.stderr)
        return 2
    checks = check_cameras(emb, states, images, a.shift_cm / 100.0, a.turn_deg)
    out = a.out or a.dataset / CHECK_IMAGE_IN_DATASET
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), overlay_grid(emb, states, images, checks)[..., ::-1])
    report = {k: vars(c) for k, c in checks.items()}
    out.with_suffix(".json").write_text(json.dumps(report, indent=1) + "\n")
    for c in checks.values():
        verdict = f"FLAGGED: {c.reason}" if c.flagged else "ok"
        print(f"{c.key}: outline-to-edge {c.score_px:.2f} px over {c.frames_scored} frames "
              f"(best moved camera: {c.best_move_score_px:.2f} px); {verdict}")  # fmt: skip
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return 1 if any(c.flagged for c in checks.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
