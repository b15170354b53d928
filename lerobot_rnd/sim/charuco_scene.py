"""A MuJoCo scene holding a ChArUco board and free pinhole cameras, where every pose is known: the ground truth
for testing :mod:`lerobot_rnd.calibration` and a stand-in for a real calibration session.

The board is a plane textured with :meth:`ChArUcoBoard.image`, carried by a mocap body, so it can lie on the
table (``T_world_board``) or ride on a simulated gripper. Cameras are world-body cameras whose pose is set per
image (``T_world_cam``, OpenCV frame); their intrinsics are MuJoCo's: ``fy = fx = 0.5 H / tan(fovy / 2)``,
principal point at the image centre.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import cv2
import numpy as np

from lerobot_rnd.arrays import invert_pose, look_at, make_pose  # noqa: F401  (look_at: for its users)
from lerobot_rnd.calibration.charuco import ChArUcoBoard

_MJ_FROM_CV = np.diag([1.0, -1.0, -1.0])  # MuJoCo cameras look along -z with y up; OpenCV's along +z, y down
# the board frame (origin at the top-left corner, x right, y down the image, z into the board) in the plane geom's
# frame (centred, texture's top row at +y): rotation diag(1, -1, -1), origin at (-w/2, +h/2, 0)


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


class ChArUcoScene:
    """``cameras``: name -> (H, W, fovy_deg). ``T_world_board`` (4, 4): the board's pose (OpenCV board frame)."""

    def __init__(
        self,
        board: ChArUcoBoard,
        cameras: Mapping[str, tuple[int, int, float]],
        T_world_board: np.ndarray | None = None,
        px_per_square: int = 120,
    ):
        import mujoco

        self.board = board
        self.cameras = {k: (int(h), int(w), float(f)) for k, (h, w, f) in cameras.items()}
        bw, bh = board.size_m
        self._T_geom_board = make_pose(np.diag([1.0, -1.0, -1.0]), np.array([-bw / 2, bh / 2, 0.0]))
        ok, png = cv2.imencode(".png", cv2.cvtColor(board.image(px_per_square), cv2.COLOR_GRAY2BGR))
        assert ok
        off_h = max(h for h, _, _ in self.cameras.values())
        off_w = max(w for _, w, _ in self.cameras.values())
        cams = "\n".join(f'<camera name="{k}" pos="0 0 1" fovy="{f}"/>' for k, (_, _, f) in self.cameras.items())
        xml = f"""<mujoco>
  <asset><texture name="board" type="2d" file="board.png"/>
    <material name="board" texture="board" texrepeat="1 1" texuniform="false"/></asset>
  <visual><global offwidth="{off_w}" offheight="{off_h}"/><quality shadowsize="0"/>
    <headlight ambient="0.85 0.85 0.85" diffuse="0.15 0.15 0.15" specular="0 0 0"/></visual>
  <worldbody>
    <geom type="plane" size="1 1 0.01" pos="0 0 -0.002" rgba="0.45 0.42 0.4 1"/>
    <body name="board" mocap="true"><geom type="plane" size="{bw / 2} {bh / 2} 0.01" material="board"/></body>
    {cams}
  </worldbody>
</mujoco>"""
        self.model = mujoco.MjModel.from_xml_string(xml, assets={"board.png": png.tobytes()})
        self.data = mujoco.MjData(self.model)
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self.set_board(np.eye(4) if T_world_board is None else T_world_board)

    def set_board(self, T_world_board: np.ndarray) -> None:
        """Places the board so that its OpenCV board frame is at ``T_world_board`` (4, 4)."""
        T_world_geom = np.asarray(T_world_board, dtype=np.float64) @ invert_pose(self._T_geom_board)
        self.data.mocap_pos[0] = T_world_geom[:3, 3]
        self.data.mocap_quat[0] = _quat_wxyz(T_world_geom[:3, :3])

    def K(self, name: str) -> np.ndarray:
        """The camera's intrinsics (3, 3), pixel centres at integer coordinates."""
        H, W, fovy = self.cameras[name]
        f = 0.5 * H / math.tan(math.radians(fovy) / 2)
        return np.array([[f, 0.0, (W - 1) / 2], [0.0, f, (H - 1) / 2], [0.0, 0.0, 1.0]])

    def render(self, name: str, T_world_cam: np.ndarray) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of camera ``name`` placed at ``T_world_cam`` (4, 4, OpenCV camera frame)."""
        import mujoco

        H, W, _ = self.cameras[name]
        cid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, name)
        T = np.asarray(T_world_cam, dtype=np.float64)
        self.model.cam_pos[cid] = T[:3, 3]
        self.model.cam_quat[cid] = _quat_wxyz(T[:3, :3] @ _MJ_FROM_CV)
        mujoco.mj_forward(self.model, self.data)
        if (H, W) not in self._renderers:
            self._renderers[(H, W)] = mujoco.Renderer(self.model, H, W)
        r = self._renderers[(H, W)]
        r.update_scene(self.data, camera=name)
        return r.render().copy()

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
