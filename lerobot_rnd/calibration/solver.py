"""Camera intrinsics and camera poses from ChArUco views at known end-effector poses.

Two set-ups, each one least-squares problem over board-corner reprojection errors (pixels):

- ``board_on="table"``: the board lies still in the robot's workspace and the arm moves. A wrist camera's
  ``T_ee_cam`` and the board's ``T_world_board`` come from hand-eye calibration (OpenCV's
  ``calibrateRobotWorldHandEye``, then refined); a static camera that sees the board in the same frames gets
  ``T_world_cam = T_world_board @ T_board_cam``. Needs at least one wrist camera.
- ``board_on="gripper"``: the board is fixed to the gripper and the arm moves it in front of static cameras
  (eye-to-hand, OpenCV's ``calibrateHandEye`` on inverted arm poses, then refined): ``T_world_cam`` and
  ``T_ee_board``. Wrist cameras cannot be calibrated this way.

Frames: ``world`` is the frame of the arm poses ``T_world_ee`` (the robot base for a LeRobot arm whose FK starts
there); camera frames are OpenCV's (x right, y down, z forward). Intrinsics are OpenCV's pinhole ``K`` (pixel
centres at integer coordinates, as R&D's ``CameraCalibration``) plus the distortion vector (k1, k2, p1, p2, k3),
which R&D's renderer does not model: :func:`distortion_shift_px` says how much it matters.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lerobot_rnd.arrays import invert_pose, make_pose
from lerobot_rnd.calibration.charuco import BoardView

BOARD_PLACEMENTS = ("table", "gripper")
CAMERA_MOUNTS = ("static", "wrist")
MIN_INTRINSICS_VIEWS = 4


@dataclass
class Intrinsics:
    """``K`` (3, 3), ``dist`` (5,) OpenCV distortion, ``image_size`` (H, W), ``rms_px`` over ``n_views`` views;
    ``model``: "full" or "focal_only" (see :func:`calibrate_intrinsics`)."""

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    rms_px: float
    n_views: int
    model: str = "full"

    def to_dict(self) -> dict:
        return {"format": "lerobot_rnd.intrinsics", "K": self.K.tolist(), "dist": self.dist.tolist(),
                "image_size": list(self.image_size), "rms_px": self.rms_px, "n_views": self.n_views, "model": self.model}  # fmt: skip

    @classmethod
    def from_dict(cls, d) -> Intrinsics:
        missing = {"K", "image_size"} - set(d)
        if missing:
            raise ValueError(f"intrinsics JSON: missing {sorted(missing)}")
        return cls(np.asarray(d["K"], float), np.asarray(d.get("dist", np.zeros(5)), float).reshape(-1)[:5],
                   tuple(int(v) for v in d["image_size"]), float(d.get("rms_px", float("nan"))), int(d.get("n_views", 0)),
                   str(d.get("model", "full")))  # fmt: skip


@dataclass
class CameraSolution:
    """One camera's pose: ``T_world_cam`` (static) or ``T_ee_cam`` (wrist), its board-reprojection error (RMS and
    max, pixels, after the joint fit) over ``n_views`` frames, and the frames whose error stands out."""

    name: str
    mount: str
    intrinsics: Intrinsics
    T_world_cam: np.ndarray | None = None
    T_ee_cam: np.ndarray | None = None
    rms_px: float = float("nan")
    max_px: float = float("nan")
    n_views: int = 0
    outlier_frames: list[int] = field(default_factory=list)


@dataclass
class RigSolution:
    cameras: dict[str, CameraSolution]
    board_on: str
    T_world_board: np.ndarray | None = None  # board_on="table"
    T_ee_board: np.ndarray | None = None  # board_on="gripper"


# ---------------------------------------------------------------------- intrinsics
def _views_alike(views: Sequence[BoardView], tol_px: float) -> bool:
    """True when every view shows the board where the first does (a still board seen by a still camera)."""
    ref = dict(zip(views[0].ids.tolist(), views[0].pixels))
    for v in views[1:]:
        for i, p in zip(v.ids.tolist(), v.pixels):
            if i in ref and np.linalg.norm(p - ref[i]) > tol_px:
                return False
    return True


def calibrate_intrinsics(
    views: Sequence[BoardView | None],
    image_size: tuple[int, int],
    fit_distortion: bool = True,
    name: str = "camera",
    still_tol_px: float = 3.0,
) -> Intrinsics:
    """Pinhole intrinsics (and distortion) of one camera from its board views (None entries are skipped).

    Views of the board in different places give the full model (fx, fy, cx, cy, distortion). When the board
    never moved in the image (a static camera over a still board: every view alike within ``still_tol_px``) only
    the focal length can be found, from the board's tilt: ``model="focal_only"``, square pixels, principal point
    at the image centre, no distortion.
    """
    used = [v for v in views if v is not None and len(v) >= 6]
    if not used:
        raise ValueError(f"camera '{name}': the board was found in no image")
    H, W = (int(v) for v in image_size)
    if _views_alike(used, still_tol_px):
        best = max(used, key=len)
        K0 = np.array([[max(H, W), 0.0, (W - 1) / 2], [0.0, max(H, W), (H - 1) / 2], [0.0, 0.0, 1.0]])
        flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
                 | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)  # fmt: skip
        rms, K, _, _, _ = cv2.calibrateCamera([best.points_board.astype(np.float32)],
                                              [best.pixels.astype(np.float32).reshape(-1, 1, 2)], (W, H), K0, None,
                                              flags=flags)  # fmt: skip
        return Intrinsics(K.astype(np.float64), np.zeros(5), (H, W), float(rms), len(used), model="focal_only")
    if len(used) < MIN_INTRINSICS_VIEWS:
        raise ValueError(
            f"camera '{name}': the board was found in {len(used)} images, intrinsics need at least "
            f"{MIN_INTRINSICS_VIEWS} (better 15+, with the board tilted and in every part of the image)"
        )
    obj = [v.points_board.astype(np.float32) for v in used]
    img = [v.pixels.astype(np.float32).reshape(-1, 1, 2) for v in used]
    flags = 0 if fit_distortion else (cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, (W, H), None, None, flags=flags)
    return Intrinsics(K.astype(np.float64), dist.reshape(-1)[:5].astype(np.float64), (H, W), float(rms), len(used))


def distortion_shift_px(
    intr: Intrinsics, grid: int = 21, region: tuple[float, float, float, float] | None = None
) -> float:
    """Largest distance (pixels) between where the distortion model and the pinhole model put a point, over a grid
    covering the image or ``region`` (u0, v0, u1, v1): what R&D's pinhole renderer gets wrong when the images are
    not undistorted. Pass the area the board covered: outside it a fitted distortion is extrapolation."""
    H, W = intr.image_size
    u0, v0, u1, v1 = region if region is not None else (0.0, 0.0, W - 1.0, H - 1.0)
    u, v = np.meshgrid(np.linspace(u0, u1, grid), np.linspace(v0, v1, grid))
    pix = np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2).astype(np.float64)
    # normalised pinhole coordinates of each distorted pixel (iterated to convergence: the default 5 iterations
    # are percent-level off for strong lenses)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rays = cv2.undistortPointsIter(pix, intr.K, intr.dist, None, None, crit)
    pin = rays.reshape(-1, 2) @ intr.K[:2, :2].T + intr.K[:2, 2]
    return float(np.linalg.norm(pin - pix.reshape(-1, 2), axis=1).max())


def board_pose(view: BoardView, intr: Intrinsics) -> np.ndarray:
    """``T_cam_board`` (4, 4) of one view (planar PnP, then iterative refinement)."""
    obj, img = view.points_board.astype(np.float64), view.pixels.astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, intr.K, intr.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, intr.K, intr.dist)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, intr.K, intr.dist, rvec, tvec)
    return make_pose(cv2.Rodrigues(rvec)[0], tvec.reshape(3))


# ---------------------------------------------------------------------- the rig
def _pose_to_vec(T: np.ndarray) -> np.ndarray:
    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])


def _vec_to_pose(x: np.ndarray) -> np.ndarray:
    return make_pose(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:6])


def _hand_eye_table(T_world_ee: list[np.ndarray], T_cam_board: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form ``(T_ee_cam, T_world_board)`` for a wrist camera and a still board (OpenCV returns the
    board-from-world and camera-from-EE transforms)."""
    T_ee_world = [invert_pose(T) for T in T_world_ee]
    R_bw, t_bw, R_ce, t_ce = cv2.calibrateRobotWorldHandEye(
        [T[:3, :3] for T in T_cam_board], [T[:3, 3] for T in T_cam_board],
        [T[:3, :3] for T in T_ee_world], [T[:3, 3] for T in T_ee_world],
    )  # fmt: skip
    return invert_pose(make_pose(R_ce, t_ce.reshape(3))), invert_pose(make_pose(R_bw, t_bw.reshape(3)))


def _hand_eye_gripper(T_world_ee: list[np.ndarray], T_cam_board: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form ``(T_world_cam, T_ee_board)`` for a static camera and a board on the gripper (eye-to-hand:
    OpenCV's hand-eye solver fed with inverted arm poses returns ``T_world_cam``)."""
    T_ee_world = [invert_pose(T) for T in T_world_ee]
    R, t = cv2.calibrateHandEye(
        [T[:3, :3] for T in T_ee_world], [T[:3, 3] for T in T_ee_world],
        [T[:3, :3] for T in T_cam_board], [T[:3, 3] for T in T_cam_board],
    )  # fmt: skip
    T_world_cam = make_pose(R, t.reshape(3))
    T_ee_board = np.mean([invert_pose(Twe) @ T_world_cam @ Tcb for Twe, Tcb in zip(T_world_ee, T_cam_board)], axis=0)
    return T_world_cam, _nearest_rigid(T_ee_board)


def _nearest_rigid(T: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(T[:3, :3])
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return make_pose(R, T[:3, 3])


def solve_rig(
    T_world_ee: np.ndarray,
    views: Mapping[str, Sequence[BoardView | None]],
    intrinsics: Mapping[str, Intrinsics],
    mounts: Mapping[str, str],
    board_on: str = "table",
    min_views: int = 5,
) -> RigSolution:
    """Poses of every camera from board views at known arm poses.

    ``T_world_ee`` (F, 4, 4): the arm pose of each frame. ``views[cam]``: F entries, the board seen by ``cam`` in
    that frame or None. ``mounts[cam]``: "static" or "wrist". Initialised in closed form (OpenCV hand-eye), then
    all poses are refined together by robust least squares on corner reprojection (pixels).
    """
    if board_on not in BOARD_PLACEMENTS:
        raise ValueError(f"board_on must be one of {BOARD_PLACEMENTS}, got {board_on!r}")
    T_world_ee = np.asarray(T_world_ee, dtype=np.float64)
    F = T_world_ee.shape[0]
    names = list(views)
    for c in names:
        if mounts.get(c) not in CAMERA_MOUNTS:
            raise ValueError(f"camera '{c}': mount must be one of {CAMERA_MOUNTS}, got {mounts.get(c)!r}")
        if len(views[c]) != F:
            raise ValueError(f"camera '{c}': {len(views[c])} views for {F} arm poses")
    wrist = [c for c in names if mounts[c] == "wrist"]
    static = [c for c in names if mounts[c] == "static"]
    if board_on == "table" and not wrist:
        raise ValueError(
            "with the board on the table the cameras' poses are fixed through a wrist camera; with static "
            "cameras only, fix the board to the gripper and pass board_on='gripper' (--board-on gripper)"
        )
    if board_on == "gripper" and wrist:
        raise ValueError(
            f"wrist cameras {wrist} move with a board fixed to the gripper and cannot be calibrated from it: "
            "calibrate them with the board on the table (--board-on table)"
        )
    seen = {c: [f for f in range(F) if views[c][f] is not None] for c in names}
    for c in names:
        if len(seen[c]) < min_views:
            raise ValueError(
                f"camera '{c}': the board was found in {len(seen[c])} frames; its pose needs at least {min_views} "
                "(at different arm poses)"
            )
    T_cam_board = {c: {f: board_pose(views[c][f], intrinsics[c]) for f in seen[c]} for c in names}

    # closed-form start
    init: dict[str, np.ndarray] = {}
    if board_on == "table":
        c0 = max(wrist, key=lambda c: len(seen[c]))
        _, T_world_board = _hand_eye_table([T_world_ee[f] for f in seen[c0]], [T_cam_board[c0][f] for f in seen[c0]])
        for c in wrist:
            init[c], _ = _hand_eye_table([T_world_ee[f] for f in seen[c]], [T_cam_board[c][f] for f in seen[c]])
        for c in static:
            f = seen[c][0]
            init[c] = T_world_board @ invert_pose(T_cam_board[c][f])
        shared = T_world_board
    else:
        c0 = max(static, key=lambda c: len(seen[c]))
        _, shared = _hand_eye_gripper([T_world_ee[f] for f in seen[c0]], [T_cam_board[c0][f] for f in seen[c0]])
        for c in static:
            init[c], _ = _hand_eye_gripper([T_world_ee[f] for f in seen[c]], [T_cam_board[c][f] for f in seen[c]])

    def cam_from_board(c: str, f: int, cam_pose: np.ndarray, board: np.ndarray) -> np.ndarray:
        if board_on == "table":
            T_world_cam = cam_pose if mounts[c] == "static" else T_world_ee[f] @ cam_pose
            return invert_pose(T_world_cam) @ board
        return invert_pose(cam_pose) @ T_world_ee[f] @ board

    def residuals(x: np.ndarray, per_obs: bool = False):
        board = _vec_to_pose(x[:6])
        out = []
        for i, c in enumerate(names):
            cam_pose = _vec_to_pose(x[6 * (i + 1) : 6 * (i + 2)])
            intr = intrinsics[c]
            for f in seen[c]:
                T = cam_from_board(c, f, cam_pose, board)
                v = views[c][f]
                proj, _ = cv2.projectPoints(v.points_board, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], intr.K, intr.dist)
                out.append((c, f, proj.reshape(-1, 2) - v.pixels))
        return out if per_obs else np.concatenate([r.ravel() for _, _, r in out])

    x0 = np.concatenate([_pose_to_vec(shared)] + [_pose_to_vec(init[c]) for c in names])
    fit = least_squares(residuals, x0, loss="soft_l1", f_scale=1.0, x_scale="jac")
    x = fit.x
    per_obs = residuals(x, per_obs=True)
    sols: dict[str, CameraSolution] = {}
    for i, c in enumerate(names):
        pose = _vec_to_pose(x[6 * (i + 1) : 6 * (i + 2)])
        errs = {f: np.linalg.norm(r, axis=1) for cc, f, r in per_obs if cc == c}
        allerr = np.concatenate(list(errs.values()))
        per_frame = {f: float(np.sqrt(np.mean(e**2))) for f, e in errs.items()}
        med = float(np.median(list(per_frame.values())))
        outliers = sorted(f for f, e in per_frame.items() if e > max(3.0 * med, 1.0))
        sol = CameraSolution(c, mounts[c], intrinsics[c], rms_px=float(np.sqrt(np.mean(allerr**2))),
                             max_px=float(allerr.max()), n_views=len(seen[c]), outlier_frames=outliers)  # fmt: skip
        if board_on == "table" and mounts[c] == "wrist":
            sol.T_ee_cam = pose
        else:
            sol.T_world_cam = pose
        sols[c] = sol
    board = _vec_to_pose(x[:6])
    if board_on == "table":
        return RigSolution(sols, board_on, T_world_board=board)
    return RigSolution(sols, board_on, T_ee_board=board)
