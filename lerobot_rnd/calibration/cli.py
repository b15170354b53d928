"""``lerobot-rnd-calibrate``: a printable ChArUco board, and every camera's intrinsics and pose from views of it.

    lerobot-rnd-calibrate board --out board.png                  # print it at 100%, measure a square
    lerobot-rnd-calibrate solve --board board.json --robot so101 --wrist observation.images.wrist \\
        --dataset ~/.cache/huggingface/lerobot/me/so101_calib     # writes <dataset>/meta/rnd_embodiment.json

``solve`` reads frames and the arm's state from a LeRobot dataset (``--dataset``; record it with
``lerobot-record`` while the board lies still and you move the arm to 20-40 poses, pausing at each) or from a
folder (``--images``: ``<folder>/<camera key>/<frame>.png`` and ``<folder>/states.csv`` with a ``frame`` column
and the state's values). docs/CALIBRATION.md has the walk-through.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.calibration.charuco import MM_PER_INCH, BoardView, ChArUcoBoard
from lerobot_rnd.calibration.solver import (
    BOARD_PLACEMENTS,
    Intrinsics,
    RigSolution,
    calibrate_intrinsics,
    distortion_shift_px,
    solve_rig,
)
from lerobot_rnd.camera_calibration import CameraCalibration
from lerobot_rnd.embodiment import EMBODIMENT_FILE_IN_DATASET, Embodiment, load_embodiment

IMAGE_PREFIX = "observation.images."
REPORT_FILE_IN_DATASET = "meta/rnd_calibration_report.json"
ROBOTS = ("so101",)


class CalibrationUsageError(ValueError):
    """A bad flag or input: printed as one ``error:`` line."""


# ---------------------------------------------------------------------- inputs
def _camera_key(name: str) -> str:
    return name if name.startswith(IMAGE_PREFIX) else IMAGE_PREFIX + name


def _moving(states: np.ndarray, max_motion: float | None) -> np.ndarray:
    """(F,) bool: frames whose state changes by more than ``max_motion`` (state units) to a neighbour frame."""
    if max_motion is None or len(states) < 2:
        return np.zeros(len(states), bool)
    step = np.abs(np.diff(states, axis=0)).max(axis=1)
    prev = np.concatenate([[0.0], step])
    nxt = np.concatenate([step, [0.0]])
    return np.maximum(prev, nxt) > max_motion


def frames_from_folder(folder: Path, cameras: Sequence[str] | None) -> tuple[np.ndarray, dict[str, list[np.ndarray]]]:
    """States (F, D) and RGB images per camera key from ``<folder>/<camera>/<frame>.png`` + ``states.csv``."""
    csv_path = folder / "states.csv"
    if not csv_path.is_file():
        raise CalibrationUsageError(f"--images {folder}: no states.csv (columns: frame, then the state's values)")
    with csv_path.open() as f:
        rows = list(csv.reader(f))
    if len(rows) < 2 or rows[0][0] != "frame":
        raise CalibrationUsageError(f"{csv_path}: the first column must be 'frame', one row per frame")
    frames = [r[0] for r in rows[1:]]
    states = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    dirs = sorted(d for d in folder.iterdir() if d.is_dir())
    if cameras:
        dirs = [d for d in dirs if _camera_key(d.name) in {_camera_key(c) for c in cameras}]
    if not dirs:
        raise CalibrationUsageError(f"--images {folder}: no camera folders (<folder>/<camera key>/<frame>.png)")
    images: dict[str, list[np.ndarray]] = {}
    for d in dirs:
        imgs = []
        for fr in frames:
            p = next((d / f"{fr}{ext}" for ext in (".png", ".jpg", ".jpeg") if (d / f"{fr}{ext}").is_file()), None)
            if p is None:
                raise CalibrationUsageError(f"{d}: no image for frame {fr!r} of states.csv")
            imgs.append(cv2.cvtColor(cv2.imread(str(p), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))
        images[_camera_key(d.name)] = imgs
    return states, images


def frames_from_dataset(
    root: Path, cameras: Sequence[str] | None, every: int, max_motion: float | None, max_frames: int
) -> tuple[np.ndarray, dict[str, list[np.ndarray]], dict]:
    """States and images of a LeRobot dataset's pauses: the middle frame of each run of still frames (of every
    ``every``-th pause, at most ``max_frames`` spread over the session)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    if not (root / "meta" / "info.json").is_file():
        raise CalibrationUsageError(f"--dataset {root}: not a LeRobot dataset (no meta/info.json)")
    ds = LeRobotDataset(f"local/{root.name}", root=root, video_backend="pyav")
    keys = [k for k in ds.meta.camera_keys if not cameras or k in {_camera_key(c) for c in cameras}]
    if not keys:
        raise CalibrationUsageError(f"--dataset {root}: no camera among {ds.meta.camera_keys} matches --cameras")
    states = torch.stack([torch.as_tensor(s) for s in ds.hf_dataset["observation.state"]]).double().numpy()
    episodes = np.asarray(ds.hf_dataset["episode_index"])
    moving = np.zeros(len(states), bool)
    for e in np.unique(episodes):
        idx = np.flatnonzero(episodes == e)
        moving[idx] = _moving(states[idx], max_motion)
    # one frame per pause (the middle of each run of still frames, runs split by episode), at most max_frames of
    # them spread over the session
    still = np.flatnonzero(~moving)
    breaks = np.flatnonzero((np.diff(still) > 1) | (np.diff(episodes[still]) != 0)) + 1
    pauses = np.array([run[len(run) // 2] for run in np.split(still, breaks) if len(run)], dtype=int)[::every]
    candidates = pauses[np.unique(np.linspace(0, len(pauses) - 1, min(max_frames, len(pauses))).round().astype(int))] if len(pauses) else pauses
    info = {"frames": len(states), "still": len(still), "pauses": len(pauses), "used": len(candidates)}
    images: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    from tqdm import tqdm

    for i in tqdm(candidates, desc="reading frames", leave=False):
        item = ds[int(i)]
        for k in keys:
            img = item[k]
            img = img.permute(1, 2, 0).numpy() if isinstance(img, torch.Tensor) else np.asarray(img)
            images[k].append((img * 255.0 + 0.5).clip(0, 255).astype(np.uint8) if img.dtype != np.uint8 else img)
    return states[candidates], images, info


# ---------------------------------------------------------------------- solve
def _base_embodiment(robot: str | None, embodiment: str | None) -> tuple[Embodiment | None, object]:
    """The embodiment whose cameras the calibration replaces (None for --robot) and its EE pose source."""
    if robot is not None:
        if robot not in ROBOTS:
            raise CalibrationUsageError(f"--robot {robot!r}: known robots are {list(ROBOTS)}; or pass --embodiment")
        from lerobot_rnd.so101 import so101_ee_pose_source

        return None, so101_ee_pose_source()
    if embodiment is None:
        raise CalibrationUsageError("pass --robot so101 or --embodiment <json> (where the EE pose is in the state)")
    emb = load_embodiment(embodiment)
    return emb, emb.ee_pose_source


def _covered(views: Sequence[BoardView | None]) -> tuple[float, float, float, float]:
    """(u0, v0, u1, v1): the image area the board's corners covered over all views."""
    px = np.concatenate([v.pixels for v in views if v is not None])
    return float(px[:, 0].min()), float(px[:, 1].min()), float(px[:, 0].max()), float(px[:, 1].max())


def _pose_text(T: np.ndarray) -> str:
    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
    return f"xyz [{T[0, 3]:+.3f} {T[1, 3]:+.3f} {T[2, 3]:+.3f}] m, rpy [{rpy[0]:+.1f} {rpy[1]:+.1f} {rpy[2]:+.1f}] deg"


def calibrate(
    board: ChArUcoBoard,
    states: np.ndarray,
    images: dict[str, list[np.ndarray]],
    ee_pose_source,
    wrist: Sequence[str],
    board_on: str = "table",
    lens: str = "pinhole",
    given_intrinsics: dict[str, Intrinsics] | None = None,
) -> tuple[dict[str, CameraCalibration], RigSolution, dict]:
    """Calibrations per camera key from frames (``states`` (F, D), ``images[key]`` F RGB images) and a report.

    ``given_intrinsics``: per camera key, intrinsics from an earlier session (``lerobot-rnd-calibrate
    intrinsics``) used instead of estimating them from these frames."""
    given_intrinsics = {_camera_key(k): v for k, v in (given_intrinsics or {}).items()}
    unknown = sorted(set(given_intrinsics) - set(images))
    if unknown:
        raise CalibrationUsageError(f"--intrinsics {unknown}: not among the cameras {sorted(images)}")
    wrist = [_camera_key(w) for w in wrist]
    unknown = [w for w in wrist if w not in images]
    if unknown:
        raise CalibrationUsageError(f"--wrist {unknown}: not among the cameras {sorted(images)}")
    T_world_ee = ee_pose_source.ee_pose(torch.as_tensor(states, dtype=torch.float64)).numpy()
    views: dict[str, list[BoardView | None]] = {}
    intr = {}
    report: dict = {"board": board.to_dict(), "board_on": board_on, "lens": lens, "frames": len(states), "cameras": {}}
    for key, imgs in images.items():
        sizes = {im.shape[:2] for im in imgs}
        if len(sizes) != 1:
            raise CalibrationUsageError(f"camera {key}: images of different sizes {sorted(sizes)}")
        views[key] = [board.detect(im) for im in imgs]
        size = sizes.pop()
        entry = {"mount": "wrist" if key in wrist else "static", "image_size": list(size),
                 "board_found": sum(v is not None for v in views[key])}  # fmt: skip
        if key in given_intrinsics:
            intr[key] = given_intrinsics[key]
            if tuple(intr[key].image_size) != tuple(size):
                raise CalibrationUsageError(
                    f"--intrinsics for {key} are for {intr[key].image_size[1]}x{intr[key].image_size[0]} images, "
                    f"this camera's are {size[1]}x{size[0]}: calibrate intrinsics at the recording resolution"
                )
            entry.update(intrinsics_source="given", intrinsics_model=intr[key].model)
        else:
            try:
                pinhole = calibrate_intrinsics(views[key], size, fit_distortion=False, name=key)
                distorted = calibrate_intrinsics(views[key], size, fit_distortion=True, name=key)
            except ValueError as e:
                raise CalibrationUsageError(str(e)) from e
            intr[key] = pinhole if lens == "pinhole" else distorted
            entry.update(
                intrinsics_source="these frames", intrinsics_model=pinhole.model,
                intrinsics_rms_px={"pinhole": pinhole.rms_px, "with_distortion": distorted.rms_px},
                distortion=distorted.dist.tolist(), distortion_shift_px=distortion_shift_px(distorted, region=_covered(views[key])),
            )  # fmt: skip
        report["cameras"][key] = entry
    mounts = {k: ("wrist" if k in wrist else "static") for k in images}
    try:
        sol = solve_rig(T_world_ee, views, intr, mounts, board_on=board_on)
    except ValueError as e:
        raise CalibrationUsageError(str(e)) from e
    cams = {}
    for key, cs in sol.cameras.items():
        H, W = cs.intrinsics.image_size
        name = key.removeprefix(IMAGE_PREFIX)
        if cs.T_ee_cam is not None:
            cams[key] = CameraCalibration(name, cs.intrinsics.K, (H, W), T_ee_cam=cs.T_ee_cam)
        else:
            cams[key] = CameraCalibration(name, cs.intrinsics.K, (H, W), T_world_cam=cs.T_world_cam)
        report["cameras"][key].update(
            K=cs.intrinsics.K.tolist(), pose_rms_px=cs.rms_px, pose_max_px=cs.max_px, views=cs.n_views,
            outlier_frames=cs.outlier_frames, pose=cams[key].to_dict().get("T_ee_cam", cams[key].to_dict().get("T_world_cam")),
        )  # fmt: skip
    if sol.T_world_board is not None:
        report["T_world_board"] = sol.T_world_board.tolist()
    if sol.T_ee_board is not None:
        report["T_ee_board"] = sol.T_ee_board.tolist()
    return cams, sol, report


def print_report(report: dict, cams: dict[str, CameraCalibration]) -> None:
    print(f"{report['frames']} frames, board on the {report['board_on']}, lens model: {report['lens']}")
    for key, r in report["cameras"].items():
        c = cams[key]
        K = c.K
        pose = c.T_ee_cam if c.T_ee_cam is not None else c.T_world_cam
        frame = "T_ee_cam" if c.T_ee_cam is not None else "T_world_cam"
        print(f"{key} ({r['mount']}, {r['image_size'][1]}x{r['image_size'][0]}): board in {r['board_found']} frames")
        line = f"  intrinsics fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} cy {K[1, 2]:.1f}"
        if r["intrinsics_source"] == "given":
            print(f"{line} (given, {r['intrinsics_model']} model)")
        elif r["intrinsics_model"] == "focal_only":
            print(f"{line}: the board never moved in this camera's view, so only the focal length was estimated "
                  "(principal point at the image centre, no distortion); for better intrinsics run "
                  "`lerobot-rnd-calibrate intrinsics` on views of the board moved around in front of it and pass "
                  "--intrinsics")  # fmt: skip
        else:
            ir = r["intrinsics_rms_px"]
            print(f"{line}; reprojection RMS {ir['pinhole']:.2f} px pinhole, {ir['with_distortion']:.2f} px with lens "
                  f"distortion (where the board was seen, distortion moves image points by up to {r['distortion_shift_px']:.1f} px)")  # fmt: skip
        print(f"  {frame}: {_pose_text(pose)}; board reprojection RMS {r['pose_rms_px']:.2f} px, max {r['pose_max_px']:.2f} px")
        if r["outlier_frames"]:
            print(f"  frames that disagree (moving arm? bad joint reading?): {r['outlier_frames']}")


# ---------------------------------------------------------------------- CLI
def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="lerobot-rnd-calibrate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("board", help="write a printable ChArUco board (PNG) and its description (JSON)")
    b.add_argument("--out", type=Path, default=Path("charuco_board.png"), help="PNG path; the JSON goes beside it")
    b.add_argument("--squares", default="7x5", help="columns x rows of squares (default 7x5)")
    b.add_argument("--square-mm", type=float, default=40.0, help="printed square size in mm (default 40)")
    b.add_argument("--marker-mm", type=float, default=30.0, help="printed marker size in mm (default 30)")
    b.add_argument("--dictionary", default="DICT_5X5_100", help="OpenCV ArUco dictionary (default DICT_5X5_100)")
    b.add_argument("--dpi", type=int, default=300)
    i = sub.add_parser("intrinsics", help="one camera's intrinsics from images of the board moved around in front of it")
    i.add_argument("images", type=Path, nargs="+", help="image files or folders of them (png/jpg)")
    i.add_argument("--board", type=Path, required=True, help="the board JSON written by `board`")
    i.add_argument("--lens", choices=("pinhole", "distorted"), default="pinhole")
    i.add_argument("--out", type=Path, required=True, help="intrinsics JSON, for `solve --intrinsics KEY=FILE`")
    s = sub.add_parser("solve", help="intrinsics and poses of every camera; writes the embodiment JSON")
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument("--dataset", type=Path, help="LeRobot dataset root recorded while the board lay still")
    src.add_argument("--images", type=Path, help="folder: <camera key>/<frame>.png and states.csv")
    s.add_argument("--board", type=Path, required=True, help="the board JSON written by `board` (measured sizes)")
    s.add_argument("--square-mm", type=float, default=None, help="the square size you measured on the print, if it differs")
    rob = s.add_mutually_exclusive_group(required=True)
    rob.add_argument("--robot", choices=ROBOTS, help="a robot this package knows (EE pose, meshes, actions)")
    rob.add_argument("--embodiment", help="an embodiment JSON or preset whose cameras are replaced")
    s.add_argument("--wrist", default="", help="comma-separated camera keys mounted on the gripper")
    s.add_argument("--cameras", default="", help="comma-separated camera keys to calibrate (default: all)")
    s.add_argument("--intrinsics", action="append", default=[], metavar="KEY=FILE",
                   help="a camera's intrinsics from `lerobot-rnd-calibrate intrinsics` (repeatable)")  # fmt: skip
    s.add_argument("--board-on", choices=BOARD_PLACEMENTS, default="table")
    s.add_argument("--lens", choices=("pinhole", "distorted"), default="pinhole",
                   help="pinhole (default: what R&D renders) or OpenCV's distortion model for the poses")  # fmt: skip
    s.add_argument("--every", type=int, default=1, help="dataset: use every n-th pause")
    s.add_argument("--max-frames", type=int, default=60, help="dataset: at most this many frames")
    s.add_argument("--max-motion", type=float, default=0.5,
                   help="dataset: skip frames whose state moves more than this (state units) to a neighbour frame")  # fmt: skip
    s.add_argument("--out", type=Path, default=None, help=f"embodiment JSON (default <dataset>/{EMBODIMENT_FILE_IN_DATASET})")
    s.add_argument("--image-size", default=None, metavar="HxW",
                   help="write the calibrations for images resized to HxW (the size your datasets store, if it is "
                        "not the calibration recording's)")  # fmt: skip
    return p.parse_args(argv)


def _split(s: str) -> list[str]:
    return [x.strip() for x in s.split(",") if x.strip()]


def run(a: argparse.Namespace) -> int:
    if a.command == "board":
        try:
            cols, rows = (int(v) for v in a.squares.lower().split("x"))
        except ValueError as e:
            raise CalibrationUsageError(f"--squares {a.squares!r}: write columns x rows, e.g. 7x5") from e
        try:
            board = ChArUcoBoard((cols, rows), a.square_mm / 1000.0, a.marker_mm / 1000.0, a.dictionary)
        except ValueError as e:
            raise CalibrationUsageError(str(e)) from e
        a.out.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(a.out), board.printable(a.dpi))
        board.save_json(a.out.with_suffix(".json"))
        w, h = board.size_m
        print(f"wrote {a.out} ({w * 1000:.0f} x {h * 1000:.0f} mm board at {a.dpi} dpi, "
              f"{a.dpi / MM_PER_INCH:.2f} px/mm) and {a.out.with_suffix('.json')}")  # fmt: skip
        return 0
    if not a.board.is_file():
        raise CalibrationUsageError(f"--board {a.board}: no such file (write one with `lerobot-rnd-calibrate board`)")
    if a.command == "intrinsics":
        return run_intrinsics(ChArUcoBoard.load_json(a.board), a.images, a.lens, a.out)
    board = ChArUcoBoard.load_json(a.board)
    if a.square_mm is not None:
        ratio = a.square_mm / 1000.0 / board.square_m
        board = ChArUcoBoard(board.squares, board.square_m * ratio, board.marker_m * ratio, board.dictionary)
    base, ee_source = _base_embodiment(a.robot, a.embodiment)
    cameras = _split(a.cameras) or None
    if a.dataset is not None:
        states, images, info = frames_from_dataset(a.dataset, cameras, a.every, a.max_motion, a.max_frames)
        print(f"dataset: {info['frames']} frames, {info['still']} still in {info['pauses']} pauses, {info['used']} used "
              "(the middle frame of each pause)")  # fmt: skip
        out = a.out or a.dataset / EMBODIMENT_FILE_IN_DATASET
    else:
        states, images = frames_from_folder(a.images, cameras)
        if a.out is None:
            raise CalibrationUsageError("--images needs --out <embodiment JSON>")
        out = a.out
    given = {}
    for item in a.intrinsics:
        key, sep, path = item.partition("=")
        if not sep or not Path(path).is_file():
            raise CalibrationUsageError(f"--intrinsics {item!r}: write KEY=FILE with an existing intrinsics JSON")
        given[key] = Intrinsics.from_dict(json.loads(Path(path).read_text()))
    cams, _, report = calibrate(board, states, images, ee_source, _split(a.wrist), a.board_on, a.lens, given)
    print_report(report, cams)
    if a.image_size is not None:
        try:
            h, w = (int(v) for v in a.image_size.lower().split("x"))
        except ValueError as e:
            raise CalibrationUsageError(f"--image-size {a.image_size!r}: write HxW, e.g. 480x640") from e
        cams = {k: c.resized(h, w) for k, c in cams.items()}
        print(f"calibrations resized to {h}x{w}")
    if base is None:
        from lerobot_rnd.so101 import so101_embodiment

        mesh = {k: ("fingers" if not c.is_static else "full") for k, c in cams.items()}
        emb = so101_embodiment(cams, camera_mesh=mesh)
    else:
        emb = dataclasses.replace(base, cameras={**base.cameras, **cams})
    out.parent.mkdir(parents=True, exist_ok=True)
    emb.save_json(out)
    report_path = out.parent / Path(REPORT_FILE_IN_DATASET).name
    report_path.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out} and {report_path}")
    return 0


def run_intrinsics(board: ChArUcoBoard, paths: Sequence[Path], lens: str, out: Path) -> int:
    files = []
    for p in paths:
        files += sorted(f for f in p.iterdir() if f.suffix.lower() in (".png", ".jpg", ".jpeg")) if p.is_dir() else [p]
    missing = [str(f) for f in files if not f.is_file()]
    if missing or not files:
        raise CalibrationUsageError(f"intrinsics: no such image files {missing or [str(p) for p in paths]}")
    images = [cv2.cvtColor(cv2.imread(str(f), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for f in files]
    sizes = {im.shape[:2] for im in images}
    if len(sizes) != 1:
        raise CalibrationUsageError(f"intrinsics: images of different sizes {sorted(sizes)}")
    try:
        intr = calibrate_intrinsics([board.detect(im) for im in images], sizes.pop(), lens == "distorted")
    except ValueError as e:
        raise CalibrationUsageError(str(e)) from e
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(intr.to_dict(), indent=1) + "\n")
    K = intr.K
    print(f"board in {intr.n_views} of {len(images)} images; fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} "
          f"cy {K[1, 2]:.1f} ({intr.model} model), reprojection RMS {intr.rms_px:.2f} px; wrote {out}")  # fmt: skip
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """0 when done, 2 for a bad flag or input (one ``error:`` line on stderr)."""
    a = _parse(argv)
    try:
        return run(a)
    except CalibrationUsageError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
