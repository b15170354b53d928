"""Obtaining a camera calibration for R&D: ChArUco boards (:mod:`.charuco`), intrinsics and hand-eye poses
(:mod:`.solver`), the ``lerobot-rnd-calibrate`` command (:mod:`.cli`). The calibration itself is
:class:`lerobot_rnd.camera_calibration.CameraCalibration`."""

from lerobot_rnd.calibration.charuco import BoardView, ChArUcoBoard
from lerobot_rnd.calibration.solver import (
    CameraSolution,
    Intrinsics,
    RigSolution,
    board_pose,
    calibrate_intrinsics,
    distortion_shift_px,
    solve_rig,
)

__all__ = [
    "BoardView", "CameraSolution", "ChArUcoBoard", "Intrinsics", "RigSolution", "board_pose",
    "calibrate_intrinsics", "distortion_shift_px", "solve_rig",
]  # fmt: skip
