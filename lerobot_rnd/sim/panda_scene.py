"""The Panda suite's MuJoCo scenes: gym-hil's Franka Panda + Robotiq 2F-85 (gym-hil 0.1.14 is used only for
its assets, with decimated visual meshes) plus a floor, lights, a static ``front`` camera, a mocap body
``ee_target`` and the task objects of :data:`PANDA_TASKS`. The tasks are in :mod:`lerobot_rnd.sim.panda_env`.
"""

from __future__ import annotations

import copy
import importlib.util
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_rnd.gripper_mesh import cluster_decimate
from lerobot_rnd.sim.mujoco_env import default_headless_gl

#: the tasks that push the blue block onto a target disc (the same scene, object and expert)
BLOCK_TASKS = ("push-block", "slide-block")
#: a red and a blue cube in one scene, the task names the cube to lift: the same images for both tasks, so only the
#: task string tells them apart (issue 35's multi-task pair); task -> (the cube to lift, the other cube)
TWO_CUBE_TASKS = {"lift-red-cube": ("red_cube", "blue_cube"), "lift-blue-cube": ("blue_cube", "red_cube")}
PANDA_TASKS = ("lift-cube", "push-block", "press-button", "pick-place", "slide-block", *TWO_CUBE_TASKS)
GYM_HIL_VERSION = "0.1.14"
INSTALL_HINT = f"pip install --no-deps gym-hil=={GYM_HIL_VERSION}  (only its MuJoCo assets are used)"

#: observation camera name -> MuJoCo camera name
MUJOCO_CAMERAS = {"front": "front", "wrist": "handcam_rgb"}
EE_SITE = "pinch"
GRIPPER_ROOT_BODY = "base_mount"
#: the Robotiq's fingers (follower links with their pads): the "fingers" mesh drawn in the wrist camera
FINGER_BODIES = ("right_follower", "left_follower")

PHYSICS_DT = 0.002
#: home orientation of the EE (pointing down, fingers opening along world -y)
HOME_QUAT = np.array([0.0, 1.0, 0.0, 0.0])
#: EE (pinch) position at the start of every episode
START_POS = np.array([0.45, 0.0, 0.22])
#: static front camera: position, the point it looks at and its vertical field of view, framed on the placement
#: range (x 0.33-0.55, y +-0.15) with the gripper's start pose in view: at 128 px the 4 cm cube is 10-16 px wide
#: (``benchmarks/camera_views.py``; the first framing, 0.95 / 0.55 m away at fovy 50, gave it 8-11 px). The
#: price is headroom: the finger tips leave the top of the image above z = 0.28-0.34 m (the start pose is at 0.22)
FRONT_CAMERA_POS = (0.88, 0.0, 0.52)
FRONT_CAMERA_LOOKAT = (0.44, 0.0, 0.09)
FRONT_CAMERA_FOVY = 42.0
#: the wrist camera's (gym-hil's ``handcam_rgb``) vertical field of view; gym-hil's 42.5 degrees showed the cube at
#: the start pose only near the centre of the placement range, 60 shows it over most of the range (the gripper
#: hides the corners nearest the robot), as a wide-angle wrist camera would
WRIST_CAMERA_FOVY = 60.0

CUBE_HALF = 0.02
BLOCK_HALF = (0.025, 0.025, 0.02)
TARGET_RADIUS = 0.03
#: slide-block: the target's distance from the block along the block's local +y axis (m)
SLIDE_DISTANCE = 0.10
BUTTON_HOUSING_HALF = (0.04, 0.04, 0.025)
BUTTON_RADIUS = 0.02
BUTTON_HALF_HEIGHT = 0.008
BUTTON_TRAVEL = 0.015


def slide_target_xy(block_xy: Sequence[float], yaw: float) -> np.ndarray:
    """slide-block: (2,) world x, y (m) of the target, :data:`SLIDE_DISTANCE` along the local +y axis of a block at
    ``block_xy`` turned by ``yaw`` (rad) about the world z axis."""
    return np.asarray(block_xy, np.float64)[:2] + SLIDE_DISTANCE * np.array([-math.sin(yaw), math.cos(yaw)])


def placement_target_xy(task: str, placement: Sequence[float]) -> np.ndarray | None:
    """(2,) world x, y (m) of the target disc that ``placement`` puts down (push-block / pick-place: its last two
    numbers; slide-block: :func:`slide_target_xy` of the block), None for a task without a target."""
    p = np.asarray(placement, np.float64)
    if task in ("push-block", "pick-place"):
        return p[3:5].copy()
    if task == "slide-block":
        return slide_target_xy(p[:2], float(p[2]))
    return None


def _lookat_xyaxes(pos: Sequence[float], target: Sequence[float]) -> list[float]:
    f = np.asarray(target, float) - np.asarray(pos, float)
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    return [*right.tolist(), *up.tolist()]


def gym_hil_assets_dir() -> Path:
    spec = importlib.util.find_spec("gym_hil")
    if spec is None or spec.origin is None:
        raise ImportError(f"the Panda suite needs gym-hil's MuJoCo assets: {INSTALL_HINT}")
    d = Path(spec.origin).parent / "assets"
    if not (d / "panda.xml").exists():
        raise FileNotFoundError(f"{d / 'panda.xml'} not found: reinstall gym-hil ({INSTALL_HINT})")
    return d


#: face caps of the visual meshes (software OpenGL draws gym-hil's 190k-face arm at about 40 ms per
#: 128x128 image on a CPU; with these caps, 35k faces, about 12 ms). None keeps the original meshes.
MESH_FACE_CAPS = {"robotiq_2f85": 3000, "franka_emika_panda": 1000}
_ASSETS: dict[bool, dict[str, bytes]] = {}
_MODEL_CACHE: dict[tuple, Any] = {}


def _assets(simplify: bool = True) -> dict[str, bytes]:
    """gym-hil's asset files (``panda.xml`` and meshes) by relative path; with ``simplify`` the visual
    meshes (Panda ``.obj`` parts, Robotiq ``.stl`` parts) are decimated to :data:`MESH_FACE_CAPS`."""
    if simplify not in _ASSETS:
        root = gym_hil_assets_dir()
        assets = {
            p.relative_to(root).as_posix(): p.read_bytes()
            for p in root.rglob("*")
            if p.is_file() and p.suffix.lower() in (".xml", ".stl", ".obj", ".png")
        }
        if simplify:
            import io

            import trimesh

            for key, raw in list(assets.items()):
                folder, ext = key.split("/", 1)[0], key.rsplit(".", 1)[-1].lower()
                cap = MESH_FACE_CAPS.get(folder)
                panda_collision = folder == "franka_emika_panda" and ext == "stl"  # never drawn
                if cap is None or ext not in ("obj", "stl") or panda_collision:
                    continue
                tm = trimesh.load(io.BytesIO(raw), file_type=ext, force="mesh", process=False)
                if len(tm.faces) <= cap:
                    continue
                v, f, _ = cluster_decimate(tm.vertices, tm.faces, cap, search="grow")
                out = trimesh.Trimesh(v, f, process=False).export(file_type=ext)
                assets[key] = out.encode() if isinstance(out, str) else out
        _ASSETS[simplify] = assets
    return _ASSETS[simplify]


def _target_marker_xml(radius: float) -> str:
    """A green disc of ``radius`` on the table (visual only), body and geom ``target_marker``."""
    return f"""
    <body name="target_marker" pos="0.45 0.1 0">
      <geom name="target_marker" type="cylinder" size="{radius} 0.0005" pos="0 0 0.0005"
            contype="0" conaffinity="0" rgba=".1 .8 .2 1"/>
    </body>"""


def _free_box_xml(name: str, half: Sequence[float], mass: float, rgba: str, xy: Sequence[float] = (0.45, 0)) -> str:
    """A free box (body, joint and geom ``name``) of half extents ``half`` resting on the table at ``xy``."""
    hx, hy, hz = half
    return f"""
    <body name="{name}" pos="{xy[0]} {xy[1]} {hz}">
      <freejoint name="{name}"/>
      <geom name="{name}" type="box" size="{hx} {hy} {hz}" mass="{mass}" rgba="{rgba}"/>
    </body>"""


def _task_xml(task: str) -> str:
    if task in TWO_CUBE_TASKS:
        h = CUBE_HALF
        red = _free_box_xml("red_cube", (h, h, h), mass=0.1, rgba=".85 .12 .12 1", xy=(0.40, -0.08))
        return red + _free_box_xml("blue_cube", (h, h, h), mass=0.1, rgba=".12 .3 .9 1", xy=(0.50, 0.08))
    if task in ("lift-cube", "pick-place"):
        h = CUBE_HALF
        target = "" if task == "lift-cube" else _target_marker_xml(TARGET_RADIUS + 0.01)
        return target + _free_box_xml("cube", (h, h, h), mass=0.1, rgba=".6 .3 .6 1")
    if task in BLOCK_TASKS:
        block = _free_box_xml("block", BLOCK_HALF, mass=0.15, rgba=".15 .35 .85 1")
        return _target_marker_xml(TARGET_RADIUS) + block
    if task == "press-button":
        hx, hy, hz = BUTTON_HOUSING_HALF
        return f"""
    <body name="button_box" pos="0.45 0 0">
      <geom name="button_box" type="box" size="{hx} {hy} {hz}" pos="0 0 {hz}" rgba=".35 .35 .38 1"/>
      <body name="button" pos="0 0 {2 * hz}">
        <joint name="button" type="slide" axis="0 0 1" range="-{BUTTON_TRAVEL} 0" limited="true"
               stiffness="40" springref="0.01" damping="2"/>
        <geom name="button" type="cylinder" size="{BUTTON_RADIUS} {BUTTON_HALF_HEIGHT}"
              pos="0 0 {BUTTON_HALF_HEIGHT}" mass="0.02" rgba=".85 .1 .1 1"/>
      </body>
    </body>"""
    raise ValueError(task)


def _task_contact_xml(task: str) -> str:
    if task == "press-button":  # the housing is static (part of the world): not filtered as a parent
        return '<contact><exclude body1="button_box" body2="button"/></contact>'
    return ""


def scene_xml(
    task: str, offscreen_size: int = 640, front_pos=FRONT_CAMERA_POS, front_lookat=FRONT_CAMERA_LOOKAT
) -> str:
    """MJCF of a task scene (includes gym-hil's ``panda.xml``; load with :func:`build_model`)."""
    xy = " ".join(f"{v:.6f}" for v in _lookat_xyaxes(front_pos, front_lookat))
    fp = " ".join(f"{v:.6f}" for v in front_pos)
    return f"""<mujoco model="rnd_panda_{task}">
  <include file="panda.xml"/>
  <option timestep="{PHYSICS_DT}" noslip_iterations="5" noslip_tolerance="0"/>
  <statistic center="0.4 0 0.2" extent="0.8"/>
  <visual>
    <headlight diffuse=".4 .4 .4" ambient=".4 .4 .4"/>
    <global azimuth="160" elevation="-20" offwidth="{offscreen_size}" offheight="{offscreen_size}"/>
    <quality offsamples="0"/>
  </visual>
  <asset>
    <texture type="skybox" builtin="gradient" rgb1=".3 .5 .7" rgb2="0 0 0" width="32" height="512"/>
    <texture name="grid" type="2d" builtin="checker" width="512" height="512"
             rgb1=".1 .2 .3" rgb2=".2 .3 .4"/>
    <material name="grid" texture="grid" texrepeat="2 2" texuniform="true" reflectance="0"/>
  </asset>
  <worldbody>
    <camera name="front" pos="{fp}" xyaxes="{xy}" fovy="{FRONT_CAMERA_FOVY}"/>
    <light pos="0 0 3" dir="0 0 -1" diffuse=".6 .6 .6" specular=".3 .3 .3"/>
    <light pos="1.2 -0.5 1.0" dir="-0.7 0.4 -0.6" diffuse=".6 .6 .6" specular=".2 .2 .2"/>
    <geom name="floor" size="3 3 0.01" type="plane" material="grid"/>
    <body name="ee_target" pos="{START_POS[0]} {START_POS[1]} {START_POS[2]}" quat="0 1 0 0" mocap="true"/>
    {_task_xml(task)}
  </worldbody>
  {_task_contact_xml(task)}
</mujoco>
"""


def build_model(task: str = "lift-cube", offscreen_size: int = 640, simplify_meshes: bool = True):
    """A fresh ``mujoco.MjModel`` of the task scene (compiled once per process, then copied)."""
    default_headless_gl()
    import mujoco

    task = check_task(task)
    key = (task, int(offscreen_size), bool(simplify_meshes))
    if key not in _MODEL_CACHE:
        model = mujoco.MjModel.from_xml_string(scene_xml(task, offscreen_size), _assets(bool(simplify_meshes)))
        model.cam_fovy[model.camera(MUJOCO_CAMERAS["wrist"]).id] = WRIST_CAMERA_FOVY
        _MODEL_CACHE[key] = model
    return copy.deepcopy(_MODEL_CACHE[key])


def check_task(task: str) -> str:
    if task not in PANDA_TASKS:
        raise ValueError(f"unknown Panda task {task!r}; tasks: {', '.join(PANDA_TASKS)}")
    return task

