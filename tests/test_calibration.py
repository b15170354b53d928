"""lerobot_rnd.calibration against ground truth: a MuJoCo scene with a ChArUco board and cameras at known poses
(lerobot_rnd.sim.charuco_scene), intrinsics from MuJoCo's fovy, SO-101 arm poses from its URDF.

Tolerances stated by issue 34: reprojection < 1 px, positions < 5 mm, rotations < 1 degree. Perfect renders do
much better, so the asserts are tighter (2 mm, 0.3 degrees) to catch a frame mix-up that only costs a little.
"""

from __future__ import annotations

import csv
import json
import math

import cv2
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.arrays import invert_pose, make_pose
from lerobot_rnd.calibration import ChArUcoBoard, calibrate_intrinsics, distortion_shift_px, solve_rig
from lerobot_rnd.calibration.cli import main as calibrate_main
from lerobot_rnd.calibration.solver import Intrinsics
from lerobot_rnd.sim.charuco_scene import ChArUcoScene, look_at

pytest.importorskip("mujoco")

BOARD = ChArUcoBoard((7, 5), 0.04, 0.03)
T_WORLD_BOARD = make_pose(Rotation.from_euler("z", 100, degrees=True).as_matrix() @ np.diag([1.0, -1, -1]), [0.25, -0.1, 0.0])
BOARD_CENTRE = (T_WORLD_BOARD @ np.array([0.14, 0.10, 0.0, 1.0]))[:3]
T_WORLD_FRONT = look_at(np.array([0.75, 0.0, 0.45]), BOARD_CENTRE)
T_EE_WRIST = make_pose(Rotation.from_rotvec([0.05, -0.3, 0.1]).as_matrix(), [0.0, -0.05, 0.02])


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(position error in mm, rotation error in degrees), scipy's rotation magnitude."""
    rot = Rotation.from_matrix(T_est[:3, :3].T @ T_true[:3, :3]).magnitude()
    return float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]) * 1000), math.degrees(rot)


@pytest.fixture(scope="module")
def scene():
    sc = ChArUcoScene(BOARD, {"front": (480, 640, 50.0), "wrist": (480, 640, 70.0)}, T_WORLD_BOARD)
    yield sc
    sc.close()


@pytest.fixture(scope="module")
def table_session(scene):
    """20 frames: the board still on the table, the arm moving a wrist camera over it, a static front camera."""
    rng = np.random.default_rng(0)
    T_world_ee, wrist, front = [], [], []
    for _ in range(20):
        eye = BOARD_CENTRE + np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(0.2, 0.35)])
        T_world_cam = look_at(eye, BOARD_CENTRE + rng.normal(size=3) * 0.03, roll=rng.uniform(-0.6, 0.6))
        T_world_ee.append(T_world_cam @ invert_pose(T_EE_WRIST))
        wrist.append(BOARD.detect(scene.render("wrist", T_world_cam)))
        front.append(BOARD.detect(scene.render("front", T_WORLD_FRONT)))
    return np.array(T_world_ee), {"wrist": wrist, "front": front}


def test_printable_board_has_its_stated_size_and_is_detected():
    board = ChArUcoBoard((5, 4), 0.03, 0.02)
    page = board.printable(dpi=200, margin_mm=10)
    view = board.detect(page)
    assert view is not None and len(view) == board.n_corners == 12
    # neighbouring corners along a row are one square apart: 30 mm at 200 dpi = 236.2 px
    by_id = dict(zip(view.ids.tolist(), view.pixels))
    assert np.linalg.norm(by_id[1] - by_id[0]) == pytest.approx(30 / 25.4 * 200, abs=1.0)
    assert ChArUcoBoard.from_dict(json.loads(json.dumps(board.to_dict()))) == board


@pytest.mark.parametrize(
    "kwargs, match",
    [({"marker_m": 0.05}, "smaller than square_m"), ({"dictionary": "DICT_9X9"}, "unknown ArUco dictionary"),
     ({"squares": (2, 5)}, "at least 3x3"), ({"squares": (12, 12), "dictionary": "DICT_4X4_50"}, "too few markers")],
)  # fmt: skip
def test_bad_board_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ChArUcoBoard(**kwargs)


def test_scene_board_frame_matches_pnp_with_true_intrinsics(scene):
    """The scene's board (texture orientation, origin, size) is where it says: PnP with MuJoCo's K finds it."""
    img = scene.render("front", T_WORLD_FRONT)
    view = BOARD.detect(img)
    assert view is not None and len(view) == BOARD.n_corners
    _, rvec, tvec = cv2.solvePnP(view.points_board, view.pixels, scene.K("front"), None)
    T_cam_board = make_pose(cv2.Rodrigues(rvec)[0], tvec.reshape(3))
    pos_mm, rot_deg = pose_error(T_WORLD_FRONT @ T_cam_board, T_WORLD_BOARD)
    assert pos_mm < 1.0 and rot_deg < 0.2


def test_intrinsics_recovered_from_board_views(table_session, scene):
    _, views = table_session
    intr = calibrate_intrinsics(views["wrist"], (480, 640), fit_distortion=False)
    K = scene.K("wrist")
    assert intr.rms_px < 0.3
    assert intr.K[0, 0] == pytest.approx(K[0, 0], rel=0.005) and intr.K[1, 1] == pytest.approx(K[1, 1], rel=0.005)
    assert abs(intr.K[0, 2] - K[0, 2]) < 2.0 and abs(intr.K[1, 2] - K[1, 2]) < 2.0
    with pytest.raises(ValueError, match="intrinsics need at least"):
        calibrate_intrinsics(views["wrist"][:3], (480, 640), name="wrist")


def test_distortion_shift_of_a_known_lens():
    """k1 = -0.2 (barrel): the pinhole radius r of an image corner at distorted radius r_d solves r_d = r (1 - 0.2 r^2)."""
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
    shift = distortion_shift_px(Intrinsics(K, np.array([-0.2, 0, 0, 0, 0]), (480, 640), 0.0, 0))
    # the farthest distorted pixel is a corner; undistorting it solves r_d = r (1 - 0.2 r^2) for r
    r_d = math.hypot(319.5, 239.5) / 500.0
    r = r_d
    for _ in range(100):
        r = r_d / (1 - 0.2 * r * r)
    assert shift == pytest.approx((r - r_d) * 500.0, rel=1e-3)
    assert distortion_shift_px(Intrinsics(K, np.zeros(5), (480, 640), 0.0, 0)) < 1e-6


def test_wrist_and_static_camera_poses_with_the_board_on_the_table(table_session, scene):
    T_world_ee, views = table_session
    intr = {c: calibrate_intrinsics(views[c] if c == "wrist" else views["wrist"], (480, 640), fit_distortion=False)
            for c in ("wrist",)}  # fmt: skip
    # the static front camera sees one still view: its intrinsics cannot come from it; use MuJoCo's
    intr["front"] = Intrinsics(scene.K("front"), np.zeros(5), (480, 640), 0.0, 0)
    sol = solve_rig(T_world_ee, views, intr, {"wrist": "wrist", "front": "static"}, board_on="table")
    pos_mm, rot_deg = pose_error(sol.cameras["wrist"].T_ee_cam, T_EE_WRIST)
    assert pos_mm < 2.0 and rot_deg < 0.3
    pos_mm, rot_deg = pose_error(sol.cameras["front"].T_world_cam, T_WORLD_FRONT)
    assert pos_mm < 2.0 and rot_deg < 0.3
    pos_mm, rot_deg = pose_error(sol.T_world_board, T_WORLD_BOARD)
    assert pos_mm < 2.0 and rot_deg < 0.3
    assert sol.cameras["wrist"].rms_px < 1.0 and sol.cameras["front"].rms_px < 1.0
    assert sol.cameras["wrist"].outlier_frames == []


def test_a_frame_with_a_wrong_joint_reading_is_named(table_session, scene):
    T_world_ee, views = table_session
    T_bad = T_world_ee.copy()
    T_bad[7] = T_bad[7] @ make_pose(Rotation.from_euler("z", 4, degrees=True).as_matrix(), [0.01, 0.0, 0.0])
    intr = {"wrist": Intrinsics(scene.K("wrist"), np.zeros(5), (480, 640), 0.0, 0)}
    sol = solve_rig(T_bad, {"wrist": views["wrist"]}, intr, {"wrist": "wrist"})
    assert sol.cameras["wrist"].outlier_frames == [7]
    pos_mm, rot_deg = pose_error(sol.cameras["wrist"].T_ee_cam, T_EE_WRIST)
    assert pos_mm < 3.0 and rot_deg < 0.5  # the robust loss keeps the bad frame from dragging the answer


def test_static_camera_with_the_board_on_the_gripper(scene):
    T_ee_board = make_pose(Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix(), [0.0, 0.02, 0.05])
    rng = np.random.default_rng(1)
    T_world_ee, front = [], []
    for _ in range(15):
        # the board faces the camera, tilted by up to ~25 degrees, at 0.4-0.6 m
        # the board's z points into it: away from the camera
        at = BOARD_CENTRE + rng.normal(size=3) * 0.05 + np.array([0.0, 0.0, 0.1])
        T_world_board = look_at(at, 2 * at - T_WORLD_FRONT[:3, 3] + rng.normal(size=3) * 0.2)
        T_world_board = T_world_board @ make_pose(np.eye(3), [-0.14, -0.10, 0.0])
        scene.set_board(T_world_board)
        T_world_ee.append(T_world_board @ invert_pose(T_ee_board))
        front.append(BOARD.detect(scene.render("front", T_WORLD_FRONT)))
    scene.set_board(T_WORLD_BOARD)
    intr = {"front": Intrinsics(scene.K("front"), np.zeros(5), (480, 640), 0.0, 0)}
    sol = solve_rig(np.array(T_world_ee), {"front": front}, intr, {"front": "static"}, board_on="gripper")
    pos_mm, rot_deg = pose_error(sol.cameras["front"].T_world_cam, T_WORLD_FRONT)
    assert pos_mm < 2.0 and rot_deg < 0.3
    pos_mm, rot_deg = pose_error(sol.T_ee_board, T_ee_board)
    assert pos_mm < 2.0 and rot_deg < 0.3


def test_rig_set_ups_that_cannot_work_are_refused(table_session, scene):
    T_world_ee, views = table_session
    intr = {c: Intrinsics(scene.K(c), np.zeros(5), (480, 640), 0.0, 0) for c in views}
    with pytest.raises(ValueError, match="board_on='gripper'"):
        solve_rig(T_world_ee, {"front": views["front"]}, intr, {"front": "static"}, board_on="table")
    with pytest.raises(ValueError, match="cannot be calibrated from it"):
        solve_rig(T_world_ee, views, intr, {"wrist": "wrist", "front": "static"}, board_on="gripper")
    with pytest.raises(ValueError, match="found in 2 frames"):
        solve_rig(T_world_ee[:2], {"wrist": views["wrist"][:2]}, intr, {"wrist": "wrist"})


# ---------------------------------------------------------------------- the command, on a simulated SO-101
def _so101_session(tmp_path, n_poses=40):
    """A folder of wrist + front images of a board on the table at SO-101 joint readings (degrees), with the
    wrist camera at a known pose on the gripper: reached by IK towards views of the board, then FK."""
    from lerobot_rnd import so101

    board = ChArUcoBoard((7, 5), 0.03, 0.022)
    T_world_board = make_pose(np.diag([1.0, -1, -1]), [0.15, 0.105, 0.0])
    centre = (T_world_board @ np.array([0.105, 0.075, 0, 1]))[:3]
    T_ee_cam = make_pose(Rotation.from_euler("x", -20, degrees=True).as_matrix(), [0.0, 0.05, -0.04])
    T_world_front = look_at(np.array([0.55, 0.25, 0.35]), centre)
    rng = np.random.default_rng(0)
    eyes = centre + np.stack([rng.uniform(-0.12, 0.08, n_poses), rng.uniform(-0.12, 0.12, n_poses),
                              rng.uniform(0.15, 0.3, n_poses)], 1)  # fmt: skip
    T_view = np.stack([look_at(e, centre + rng.normal(size=3) * 0.02, up=np.array([1.0, 0, 0]), roll=rng.uniform(-0.4, 0.4))
                       for e in eyes])  # fmt: skip
    q, _ = so101._kinematics().inverse_kinematics(torch.tensor(T_view @ invert_pose(T_ee_cam)), torch.zeros(5, dtype=torch.float64))
    q_lerobot = so101.urdf_to_lerobot(torch.cat([q, torch.zeros(len(q), 1, dtype=q.dtype)], -1)).numpy()
    T_world_ee = so101.forward_kinematics(torch.tensor(q_lerobot)).numpy()
    scene = ChArUcoScene(board, {"wrist": (240, 320, 75.0), "front": (480, 640, 45.0)}, T_world_board)
    folder = tmp_path / "calib"
    for key in ("observation.images.wrist", "observation.images.front"):
        (folder / key).mkdir(parents=True)
    with (folder / "states.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", *so101.JOINT_NAMES])
        for i, (qi, Te) in enumerate(zip(q_lerobot, T_world_ee)):
            w.writerow([f"{i:03d}", *qi.tolist()])
            for key, cam, T in (("wrist", "wrist", Te @ T_ee_cam), ("front", "front", T_world_front)):
                img = scene.render(cam, T)
                cv2.imwrite(str(folder / f"observation.images.{key}" / f"{i:03d}.png"), img[..., ::-1])
    truth = {"wrist": T_ee_cam, "front": T_world_front, "K_wrist": scene.K("wrist"), "K_front": scene.K("front")}
    scene.close()
    return board, folder, truth


def test_calibrate_command_on_a_simulated_so101(tmp_path, capsys):
    board, folder, truth = _so101_session(tmp_path)
    board.save_json(tmp_path / "board.json")
    out = tmp_path / "rnd_embodiment.json"
    rc = calibrate_main(["solve", "--images", str(folder), "--board", str(tmp_path / "board.json"), "--robot", "so101",
                         "--wrist", "observation.images.wrist", "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
    printed = captured.out
    assert rc == 0, captured.err
    assert "observation.images.wrist (wrist, 320x240)" in printed and "board reprojection RMS" in printed
    from lerobot_rnd.embodiment import Embodiment

    emb = Embodiment.load_json(out)
    wrist, front = emb.cameras["observation.images.wrist"], emb.cameras["observation.images.front"]
    for got, want in ((wrist.T_ee_cam, truth["wrist"]), (front.T_world_cam, truth["front"])):
        pos_mm, rot_deg = pose_error(got, want)
        assert pos_mm < 5.0 and rot_deg < 1.0, (pos_mm, rot_deg)
    assert wrist.K[0, 0] == pytest.approx(truth["K_wrist"][0, 0], rel=0.02)
    assert emb.camera_mesh == {"observation.images.wrist": "fingers", "observation.images.front": "full"}
    report = json.loads((tmp_path / "rnd_calibration_report.json").read_text())
    assert report["cameras"]["observation.images.wrist"]["pose_rms_px"] < 1.0


def test_calibrate_command_errors_name_the_fix(tmp_path, capsys):
    assert calibrate_main(["board", "--out", str(tmp_path / "b.png"), "--squares", "7by5"]) == 2
    assert "write columns x rows" in capsys.readouterr().err
    assert calibrate_main(["board", "--out", str(tmp_path / "b.png"), "--square-mm", "20", "--marker-mm", "25"]) == 2
    assert "smaller than square_m" in capsys.readouterr().err
    assert calibrate_main(["board", "--out", str(tmp_path / "b.png")]) == 0
    assert (tmp_path / "b.json").is_file()
    (tmp_path / "imgs").mkdir()
    rc = calibrate_main(["solve", "--images", str(tmp_path / "imgs"), "--board", str(tmp_path / "b.json"),
                         "--robot", "so101", "--out", str(tmp_path / "e.json")])  # fmt: skip
    assert rc == 2 and "no states.csv" in capsys.readouterr().err
    rc = calibrate_main(["solve", "--images", str(tmp_path / "imgs"), "--board", str(tmp_path / "nope.json"), "--robot", "so101"])
    assert rc == 2 and "lerobot-rnd-calibrate board" in capsys.readouterr().err


def test_calibrate_command_reads_the_still_frames_of_a_lerobot_dataset(tmp_path, capsys):
    """The same session as a LeRobot recording: each pose held for 3 frames; a frame is still when it equals both
    neighbours."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    board, folder, truth = _so101_session(tmp_path, n_poses=24)
    board.save_json(tmp_path / "board.json")
    with (folder / "states.csv").open() as f:
        rows = list(csv.reader(f))[1:]
    keys = ("observation.images.wrist", "observation.images.front")
    images = {k: [cv2.imread(str(folder / k / f"{r[0]}.png"))[..., ::-1] for r in rows] for k in keys}
    features = {k: {"dtype": "image", "shape": images[k][0].shape, "names": ["height", "width", "channels"]} for k in keys}
    features["observation.state"] = {"dtype": "float32", "shape": (6,), "names": None}
    features["action"] = {"dtype": "float32", "shape": (6,), "names": None}
    root = tmp_path / "so101_calib"
    ds = LeRobotDataset.create("local/so101_calib", fps=30, features=features, root=root, use_videos=False)
    for i, r in enumerate(rows):
        state = np.array([float(v) for v in r[1:]], np.float32)
        for _ in range(3):
            ds.add_frame({**{k: images[k][i] for k in keys}, "observation.state": state, "action": state, "task": "calibration"})
    ds.save_episode()
    ds.finalize()
    rc = calibrate_main(["solve", "--dataset", str(root), "--board", str(tmp_path / "board.json"), "--robot", "so101",
                         "--wrist", "wrist"])  # fmt: skip
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    # still: the middle frame of each pose, plus the first and last frames (whose one neighbour is the same pose);
    # the first pause is frames 0-1 and the last 70-71, every other one frame: 24 pauses, one frame used of each
    assert "dataset: 72 frames, 26 still in 24 pauses, 24 used" in captured.out
    from lerobot_rnd.embodiment import Embodiment

    emb = Embodiment.load_json(root / "meta" / "rnd_embodiment.json")
    pos_mm, rot_deg = pose_error(emb.cameras["observation.images.wrist"].T_ee_cam, truth["wrist"])
    assert pos_mm < 5.0 and rot_deg < 1.0
