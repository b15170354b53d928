"""lerobot_rnd.embodiment: calibrations, gripper meshes, EE pose sources, JSON, validation.

References are independent of the code under test: OpenCV's projectPoints, scipy's Rotation, hand-made
MJCF / URDF files with geometry whose EE-frame position is known by construction.
"""

import json
import math

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from lerobot_rnd.embodiment import (
    EMBODIMENT_PRESETS,
    CameraCalibration,
    EEPoseSource,
    Embodiment,
    GripperMesh,
    load_embodiment,
    metaworld_sawyer_embodiment,
)


def random_pose(rng, trans_scale=0.5):
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-trans_scale, trans_scale, 3)
    return T


def simple_camera(H=96, W=128, static=True, **kw):
    K = [[100.0, 0.0, 60.3], [0.0, 105.0, 47.1], [0.0, 0.0, 1.0]]
    T = np.eye(4)
    T[:3, 3] = (0.1, -0.2, -1.0)
    if static:
        return CameraCalibration("cam", K, (H, W), T_world_cam=T, **kw)
    return CameraCalibration("cam", K, (H, W), T_ee_cam=T, **kw)


def box_mesh(center=(0, 0, 0), extents=(0.02, 0.04, 0.06), color=(0.5, 0.5, 0.5)):
    b = trimesh.creation.box(extents=extents)
    b.apply_translation(center)
    return GripperMesh.from_trimesh(b, color=color)


def small_embodiment():
    mesh = box_mesh()
    return Embodiment(
        cameras={
            "observation.images.front": simple_camera(),
            "observation.images.wrist": simple_camera(static=False),
        },
        meshes={"full": mesh, "fingers": box_mesh(extents=(0.01, 0.02, 0.03))},
        camera_mesh={"observation.images.front": "full", "observation.images.wrist": "fingers"},
        ee_pose_source=EEPoseSource(
            format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[4, 5, 6, 7], gripper_index=3
        ),
        action_adapter={"type": "ee_position_delta", "scale": 0.01},
    )


# ----------------------------------------------------------------------------- camera calibration
def test_projection_matches_opencv():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(0)
    cam = CameraCalibration(
        "c", [[300, 0, 100.5], [0, 310, 80.25], [0, 0, 1]], (160, 200), T_world_cam=random_pose(rng)
    )
    T_cam_world = np.linalg.inv(cam.T_world_cam)
    pts_cam = np.concatenate([rng.uniform(-0.3, 0.3, (50, 2)), rng.uniform(0.5, 2.0, (50, 1))], 1)
    pts_world = pts_cam @ cam.T_world_cam[:3, :3].T + cam.T_world_cam[:3, 3]
    rvec, _ = cv2.Rodrigues(T_cam_world[:3, :3])
    ref, _ = cv2.projectPoints(pts_world, rvec, T_cam_world[:3, 3], cam.K, None)
    uv, z = cam.project(torch.tensor(pts_world))
    np.testing.assert_allclose(uv.numpy(), ref[:, 0], atol=1e-6)
    np.testing.assert_allclose(z.numpy(), pts_cam[:, 2], atol=1e-9)


def test_resized_maps_pixel_coordinates():
    """Resizing by s maps continuous pixel coordinates u -> (u + 0.5) s - 0.5 (pixel-centre convention)."""
    rng = np.random.default_rng(1)
    cam = simple_camera(H=96, W=128)
    pts = (
        cam.T_world_cam[:3, 3]
        + (
            cam.T_world_cam[:3, :3]
            @ np.concatenate([rng.uniform(-0.3, 0.3, (20, 2)), rng.uniform(0.8, 1.5, (20, 1))], 1).T
        ).T
    )
    uv, _ = cam.project(torch.tensor(pts))
    for H2, W2 in [(48, 64), (192, 256), (96, 64)]:
        c2 = cam.resized(H2, W2)
        assert c2.image_size == (H2, W2)
        uv2, _ = c2.project(torch.tensor(pts))
        sx, sy = W2 / 128, H2 / 96
        np.testing.assert_allclose(uv2[:, 0].numpy(), (uv[:, 0].numpy() + 0.5) * sx - 0.5, atol=1e-9)
        np.testing.assert_allclose(uv2[:, 1].numpy(), (uv[:, 1].numpy() + 0.5) * sy - 0.5, atol=1e-9)
    back = cam.resized(192, 256).resized(96, 128)
    np.testing.assert_allclose(back.K, cam.K, atol=1e-12)


def test_rotated_180_mirrors_pixels():
    rng = np.random.default_rng(2)
    cam = simple_camera(H=96, W=128)
    pts = (
        cam.T_world_cam[:3, 3]
        + (
            cam.T_world_cam[:3, :3]
            @ np.concatenate([rng.uniform(-0.3, 0.3, (20, 2)), rng.uniform(0.8, 1.5, (20, 1))], 1).T
        ).T
    )
    uv, _ = cam.project(torch.tensor(pts))
    uvf, _ = cam.rotated_180().project(torch.tensor(pts))
    np.testing.assert_allclose(uvf[:, 0].numpy(), 127 - uv[:, 0].numpy(), atol=1e-9)
    np.testing.assert_allclose(uvf[:, 1].numpy(), 95 - uv[:, 1].numpy(), atol=1e-9)


def test_camera_pose_for_ee_poses():
    rng = np.random.default_rng(3)
    T_we = torch.tensor(np.stack([random_pose(rng) for _ in range(5)]))
    static = simple_camera()
    out = static.T_world_cam_at(T_we)
    assert out.shape == (5, 4, 4)
    np.testing.assert_allclose(out.numpy(), np.broadcast_to(static.T_world_cam, (5, 4, 4)), atol=1e-12)
    mounted = simple_camera(static=False)
    out = mounted.T_world_cam_at(T_we)
    for i in range(5):
        np.testing.assert_allclose(out[i].numpy(), T_we[i].numpy() @ mounted.T_ee_cam, atol=1e-12)
    track = simple_camera(static=False, ee_follow_rotation=False)
    out = track.T_world_cam_at(T_we)
    for i in range(5):  # orientation fixed in the world, position follows the EE
        np.testing.assert_allclose(out[i, :3, :3].numpy(), track.T_ee_cam[:3, :3], atol=1e-12)
        np.testing.assert_allclose(
            out[i, :3, 3].numpy(), T_we[i, :3, 3].numpy() + track.T_ee_cam[:3, 3], atol=1e-12
        )
    with pytest.raises(ValueError, match="T_world_ee"):
        mounted.T_world_cam_at(None)


def test_calibration_json_round_trip():
    for cam in (simple_camera(), simple_camera(static=False, ee_follow_rotation=False)):
        d = json.loads(json.dumps(cam.to_dict()))
        back = CameraCalibration.from_dict(d)
        np.testing.assert_array_equal(back.K, cam.K)
        assert back.image_size == cam.image_size and back.ee_follow_rotation == cam.ee_follow_rotation
        for a in ("T_world_cam", "T_ee_cam"):
            assert (getattr(back, a) is None) == (getattr(cam, a) is None)
            if getattr(cam, a) is not None:
                np.testing.assert_array_equal(getattr(back, a), getattr(cam, a))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"K": np.eye(4)}, "K must have shape"),
        ({"K": [[-1, 0, 1], [0, 1, 1], [0, 0, 1]]}, "positive focal"),
        ({"K": [[1, 0, 1], [0, 1, 1], [0, 1, 1]]}, r"\[0, 0, 1\]"),
        ({"image_size": (0, 10)}, "image_size"),
        ({"T_world_cam": np.diag([2.0, 1, 1, 1])}, "non-orthonormal"),
        ({"T_world_cam": np.diag([-1.0, 1, 1, 1])}, "reflection"),
        ({"T_world_cam": None}, "exactly one"),
        ({"T_ee_cam": np.eye(4)}, "exactly one"),
    ],
)
def test_calibration_validation(kwargs, match):
    base = {"name": "c", "K": np.eye(3), "image_size": (4, 4), "T_world_cam": np.eye(4)}
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        CameraCalibration(**base)


# ----------------------------------------------------------------------------- meshes
def test_mesh_json_round_trip_and_validation():
    m = box_mesh(center=(0.01, 0.02, 0.03))
    back = GripperMesh.from_dict(json.loads(json.dumps(m.to_dict())))
    np.testing.assert_allclose(back.vertices, m.vertices, atol=1e-6)
    np.testing.assert_array_equal(back.faces, m.faces)
    np.testing.assert_allclose(back.vertex_colors, m.vertex_colors, atol=1e-4)
    with pytest.raises(ValueError, match="out of range"):
        GripperMesh(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(ValueError, match="vertices must have shape"):
        GripperMesh(np.zeros((3, 2)), [[0, 1, 2]])


def test_symmetry_texture_splits_colours_by_side():
    # an off-centre box and a sphere straddling the plane y = 0, plus a box entirely on one side
    sphere = GripperMesh.from_trimesh(trimesh.creation.icosphere(subdivisions=2, radius=0.03))
    mesh = GripperMesh.concatenate([box_mesh(center=(0, 0.005, 0)), sphere, box_mesh(center=(0, -0.05, 0))])
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    tex = mesh.with_symmetry_texture(axis=1, colors=(red, blue))
    v, f, c = tex.vertices.astype(np.float64), tex.faces, tex.vertex_colors
    face_y = v[f][:, :, 1]
    face_col = c[f]
    # each face is one colour (sharp boundary) and lies on that colour's side of the plane
    assert np.all(face_col.max(1) - face_col.min(1) == 0)
    is_red = np.all(face_col[:, 0] == red, axis=1)
    is_blue = np.all(face_col[:, 0] == blue, axis=1)
    assert np.all(is_red | is_blue) and is_red.any() and is_blue.any()
    assert face_y[is_red].min() >= -1e-7 and face_y[is_blue].max() <= 1e-7

    # area is preserved by the cut
    def area(m):
        t = m.vertices[m.faces].astype(np.float64)
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()

    assert area(tex) == pytest.approx(area(mesh), rel=1e-6)
    # the surface where y > 0 is red, y < 0 blue, in the proportions of the input geometry
    red_area = area(GripperMesh(tex.vertices, tex.faces[is_red]))
    ref_v, ref_f = trimesh.intersections.slice_faces_plane(
        mesh.vertices.astype(np.float64), mesh.faces, plane_normal=[0, 1, 0], plane_origin=[0, 0, 0]
    )[:2]
    assert red_area == pytest.approx(trimesh.Trimesh(ref_v, ref_f, process=False).area, rel=1e-5)
    plain = tex.without_texture((0.2, 0.3, 0.4))
    np.testing.assert_allclose(
        plain.vertex_colors, np.broadcast_to([0.2, 0.3, 0.4], plain.vertex_colors.shape)
    )


def test_symmetry_texture_rendered():
    """Our renderer sees red on the +y side and blue on the -y side of a box centred on the plane."""
    from lerobot_rnd.rendering import MeshBatch, render

    tex = box_mesh(extents=(0.05, 0.05, 0.05)).with_symmetry_texture(axis=1)
    T_cam_obj = torch.eye(4)
    T_cam_obj[:3, :3] = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])  # cam x = +y obj
    T_cam_obj[2, 3] = 0.3
    K = torch.tensor([[200.0, 0, 31.5], [0, 200.0, 31.5], [0, 0, 1]])
    mb = MeshBatch.from_meshes([(tex.vertices, tex.faces, tex.vertex_colors)])
    out = render(mb, torch.tensor([0]), T_cam_obj[None], K[None], (64, 64))
    rgb, mask = out.rgb[0], out.mask[0]
    right, left = mask[:, 34:].clone(), mask[:, :30].clone()  # image right = +y of the object
    assert right.sum() > 100 and left.sum() > 100
    assert torch.all(rgb[0, :, 34:][right] > 0.99) and torch.all(rgb[2, :, 34:][right] < 0.01)
    assert torch.all(rgb[2, :, :30][left] > 0.99) and torch.all(rgb[0, :, :30][left] < 0.01)


@pytest.mark.parametrize("method", ["cluster", "auto"])
def test_simplified(method):
    sphere = GripperMesh.from_trimesh(trimesh.creation.icosphere(subdivisions=4, radius=0.05))  # 5120 faces
    small = box_mesh(center=(0.1, 0, 0))
    mesh = GripperMesh.concatenate([sphere, small])
    s = mesh.simplified(800, method=method)
    assert s.num_faces <= 800
    assert s.num_faces > 400
    tm = trimesh.Trimesh(s.vertices, s.faces, process=False)
    assert tm.area == pytest.approx(trimesh.Trimesh(mesh.vertices, mesh.faces).area, rel=0.08)
    # the small box (12 faces) is kept exactly
    near_box = np.abs(s.vertices[:, 0] - 0.1) < 0.02
    assert near_box.sum() == 8
    np.testing.assert_allclose(np.sort(s.vertices[near_box], 0), np.sort(small.vertices, 0), atol=1e-7)
    assert mesh.simplified(10_000).num_faces == mesh.num_faces


def test_from_files_obj_and_stl(tmp_path):
    a = trimesh.creation.box(extents=(0.01, 0.02, 0.03))
    b = trimesh.creation.icosphere(subdivisions=1, radius=0.01)
    a.export(tmp_path / "a.obj")
    b.export(tmp_path / "b.stl")
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.1)
    m = GripperMesh.from_files([tmp_path / "a.obj", tmp_path / "b.stl"], transforms=[None, T])
    assert m.num_faces == len(a.faces) + len(b.faces)
    np.testing.assert_allclose(m.bounds(), [[-0.01, -0.01, -0.015], [0.01, 0.01, 0.11]], atol=1e-6)
    with pytest.raises(FileNotFoundError):
        GripperMesh.from_files([tmp_path / "missing.stl"])


MJCF = """
<mujoco>
  <worldbody>
    <body name="arm" pos="0.3 0.2 0.5" euler="0 0 90">
      <joint name="j" type="hinge" axis="0 0 1"/>
      <geom type="box" size="0.5 0.01 0.01"/>
      <body name="hand" pos="0.1 0 0" euler="90 0 0">
        <site name="tcp" pos="0 0 0.1"/>
        <geom name="palm" type="box" size="0.01 0.02 0.03" pos="0 0 0.03"/>
        <geom name="hidden" type="sphere" size="0.5" group="3"/>
        <geom name="transparent" type="sphere" size="0.5" rgba="1 1 1 0"/>
        <body name="finger" pos="0 0.02 0.06">
          <joint name="slide" type="slide" axis="0 1 0" range="0 0.03"/>
          <geom name="pad" type="capsule" size="0.005 0.01" rgba="0 1 0 1"/>
          <geom name="tip" type="cylinder" size="0.004 0.002" pos="0 0 0.02"/>
          <geom name="knob" type="ellipsoid" size="0.003 0.004 0.005" pos="0 0.01 0"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_from_mjcf_body(tmp_path):
    path = tmp_path / "robot.xml"
    path.write_text(MJCF)
    m = GripperMesh.from_mjcf_body(str(path), "hand", qpos={"j": 0.7, "slide": 0.01})
    # geometry in the hand frame is known by construction (independent of the arm's pose)
    lo, hi = m.bounds()
    np.testing.assert_allclose(lo, [-0.01, -0.02, 0.0], atol=1e-6)
    np.testing.assert_allclose(
        hi[[0, 1]], [0.01, 0.02 + 0.01 + 0.01 + 0.004], atol=1e-6
    )  # finger + slide + knob
    np.testing.assert_allclose(hi[2], 0.06 + 0.02 + 0.002, atol=1e-6)  # tip cylinder top
    green = np.all(np.isclose(m.vertex_colors, [0, 1, 0]), axis=1)
    assert green.any()  # the capsule keeps its colour
    # EE at the tcp site: everything shifts by -0.1 along the hand z axis
    m2 = GripperMesh.from_mjcf_body(str(path), "hand", ee_site="tcp", qpos={"slide": 0.01})
    np.testing.assert_allclose(m2.vertices, m.vertices - np.array([0, 0, 0.1], np.float32), atol=1e-6)
    # only the finger subtree; explicit T_ee_body
    T = np.eye(4)
    T[:3, 3] = (1.0, 2.0, 3.0)
    f = GripperMesh.from_mjcf_body(str(path), "finger", T_ee_body=T)
    fb = GripperMesh.from_mjcf_body(str(path), "finger")
    np.testing.assert_allclose(f.vertices, fb.vertices + np.array([1.0, 2.0, 3.0], np.float32), atol=1e-5)
    no_children = GripperMesh.from_mjcf_body(str(path), "hand", include_children=False)
    assert no_children.num_faces == 12  # the palm box only (hidden / transparent geoms skipped)
    with pytest.raises(ValueError, match="no body"):
        GripperMesh.from_mjcf_body(str(path), "nope")


URDF = """<?xml version="1.0"?>
<robot name="r">
  <link name="base"/>
  <link name="flange">
    <visual><origin xyz="0 0 0.02"/><geometry><box size="0.02 0.04 0.04"/></geometry></visual>
  </link>
  <link name="finger">
    <visual><origin xyz="0 0 0"/><geometry><mesh filename="package://r/meshes/finger.stl"/></geometry></visual>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="flange"/><origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="flange"/><child link="finger"/><origin xyz="0 0 0.06"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_from_urdf_and_joint_ee_pose(tmp_path):
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(0.01, 0.01, 0.02)).export(tmp_path / "meshes" / "finger.stl")
    (tmp_path / "r.urdf").write_text(URDF)
    m = GripperMesh.from_urdf(
        tmp_path / "r.urdf", ["flange", "finger"], ee_link="flange", joint_values={"j1": 1.0, "j2": 0.03}
    )
    lo, hi = m.bounds()
    np.testing.assert_allclose(lo, [-0.01, -0.02, 0.0], atol=1e-6)
    np.testing.assert_allclose(hi, [0.01, 0.03 + 0.005, 0.06 + 0.01], atol=1e-6)
    # forward kinematics EE pose source: flange at z = 0.5 rotated by j1 about z
    src = EEPoseSource(
        format="joints", urdf_path=str(tmp_path / "r.urdf"), ee_link="flange", joint_indices=[1]
    )
    state = torch.tensor([[9.0, 0.4], [9.0, -1.2]], dtype=torch.float64)
    T = src.ee_pose(state)
    for i, q in enumerate([0.4, -1.2]):
        ref = np.eye(4)
        ref[:3, :3] = Rotation.from_euler("z", q).as_matrix()
        ref[2, 3] = 0.5
        np.testing.assert_allclose(T[i].numpy(), ref, atol=1e-6)


# ----------------------------------------------------------------------------- EE pose sources
@pytest.mark.parametrize("fmt", ["quat_wxyz", "quat_xyzw", "rotvec", "rot6d", "euler_xyz", "matrix", "none"])
def test_ee_pose_source_formats(fmt):
    rng = np.random.default_rng(4)
    R = Rotation.random(6, random_state=rng)
    pos = rng.uniform(-1, 1, (6, 3))
    mats = R.as_matrix()
    rot = {
        "quat_wxyz": np.roll(R.as_quat(), 1, axis=1),
        "quat_xyzw": R.as_quat(),
        "rotvec": R.as_rotvec(),
        "rot6d": np.concatenate([mats[:, :, 0], mats[:, :, 1]], 1),
        "euler_xyz": R.as_euler("xyz"),
        "matrix": mats.reshape(6, 9),
        "none": np.zeros((6, 0)),
    }[fmt]
    state = torch.tensor(np.concatenate([pos, [[0.5]] * 6, rot], 1))
    n = rot.shape[1]
    fixed = Rotation.from_euler("y", 90, degrees=True)
    src = EEPoseSource(
        format=fmt, position_indices=[0, 1, 2], rotation_indices=list(range(4, 4 + n)) if n else None,
        fixed_rotation=fixed.as_matrix() if fmt == "none" else None, gripper_index=3,
    )  # fmt: skip
    T = src.ee_pose(state).numpy()
    ref_R = np.broadcast_to(fixed.as_matrix(), (6, 3, 3)) if fmt == "none" else mats
    np.testing.assert_allclose(T[:, :3, :3], ref_R, atol=1e-6)
    np.testing.assert_allclose(T[:, :3, 3], pos, atol=1e-12)
    np.testing.assert_allclose(T[:, 3], np.broadcast_to([0, 0, 0, 1], (6, 4)))
    np.testing.assert_allclose(src.gripper(state).numpy(), 0.5)
    back = EEPoseSource.from_dict(json.loads(json.dumps(src.to_dict())))
    np.testing.assert_allclose(back.ee_pose(state).numpy(), T, atol=1e-12)


def test_ee_pose_source_validation():
    with pytest.raises(ValueError, match="format"):
        EEPoseSource(format="quaternion", position_indices=[0, 1, 2])
    with pytest.raises(ValueError, match="4 rotation_indices"):
        EEPoseSource(format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5])
    with pytest.raises(ValueError, match="urdf_path"):
        EEPoseSource(format="joints")
    src = EEPoseSource(format="rotvec", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5])
    with pytest.raises(ValueError, match="reads index 5"):
        src.ee_pose(torch.zeros(2, 4))


# ----------------------------------------------------------------------------- embodiment
def test_embodiment_json_round_trip(tmp_path):
    emb = small_embodiment()
    path = emb.save_json(tmp_path / "meta" / "rnd_embodiment.json")
    back = Embodiment.load_json(path)
    assert back.camera_mesh == emb.camera_mesh and back.action_adapter == emb.action_adapter
    assert back.to_dict() == json.loads(json.dumps(emb.to_dict()))
    assert load_embodiment(tmp_path).to_dict() == back.to_dict()  # dataset folder
    assert load_embodiment(str(path)).to_dict() == back.to_dict()
    with pytest.raises(FileNotFoundError, match="preset"):
        load_embodiment(tmp_path / "nothing.json")
    d = emb.ee_pose_dict()
    assert d["rotation"] == "quat_wxyz" and d["rotation_indices"] == [4, 5, 6, 7] and d["gripper_index"] == 3


def _policy_features(front=(3, 96, 128), wrist=(3, 96, 128), state=(8,), extra=None):
    from lerobot.configs.types import FeatureType, PolicyFeature

    feats = {
        "observation.images.front": PolicyFeature(FeatureType.VISUAL, front),
        "observation.images.wrist": PolicyFeature(FeatureType.VISUAL, wrist),
        "observation.state": PolicyFeature(FeatureType.STATE, state),
        "action": PolicyFeature(FeatureType.ACTION, (4,)),
    }
    if extra:
        feats[extra] = PolicyFeature(FeatureType.VISUAL, (3, 96, 128))
    return feats


def test_validate_against_features():
    emb = small_embodiment()
    emb.validate_against(_policy_features())
    dataset_feats = {
        "observation.images.front": {
            "dtype": "image",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.images.wrist": {
            "dtype": "video",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.state": {"dtype": "float32", "shape": (8,), "names": None},
    }
    emb.validate_against(dataset_feats)
    with pytest.raises(ValueError, match=r"resized\(64, 64\)"):
        emb.validate_against(_policy_features(front=(3, 64, 64)))
    emb.with_image_size(64, 64, keys=["observation.images.front"]).validate_against(
        _policy_features(front=(3, 64, 64))
    )
    with pytest.raises(ValueError, match="no camera calibration for image feature"):
        emb.validate_against(_policy_features(extra="observation.images.side"))
    emb.validate_against(_policy_features(extra="observation.images.side"), require_all_cameras=False)
    feats = _policy_features()
    del feats["observation.images.wrist"]
    with pytest.raises(ValueError, match="not a feature.*rename"):
        emb.validate_against(feats)
    with pytest.raises(ValueError, match="reads index 7"):
        emb.validate_against(_policy_features(state=(4,)))


def test_embodiment_validation():
    emb = small_embodiment()
    with pytest.raises(ValueError, match="is not a mesh"):
        Embodiment(emb.cameras, emb.meshes, camera_mesh={"observation.images.front": "palm"})
    with pytest.raises(ValueError, match="no calibration"):
        Embodiment(emb.cameras, emb.meshes, camera_mesh={"observation.images.side": "full"})
    with pytest.raises(ValueError, match="'type'"):
        Embodiment(emb.cameras, emb.meshes, action_adapter={"scale": 0.01})


def test_metaworld_preset():
    emb = metaworld_sawyer_embodiment()
    assert set(emb.cameras) == {"observation.images.corner2", "observation.images.behindGripper"}
    corner2, behind = (
        emb.cameras["observation.images.corner2"],
        emb.cameras["observation.images.behindGripper"],
    )
    assert corner2.is_static and not behind.is_static and behind.ee_follow_rotation is False
    # MuJoCo intrinsics: fovy 60 degrees -> fy = 64 / tan(30 deg); centre (W-1)/2
    assert corner2.K[1, 1] == pytest.approx(64 / math.tan(math.radians(30)))
    assert corner2.K[0, 2] == pytest.approx(63.5) and corner2.K[1, 2] == pytest.approx(63.5)
    for name in ("full", "fingers"):
        assert emb.meshes[name].num_faces <= 2000
    assert 1000 <= emb.meshes["full"].num_faces
    # the fingers open along the hand's y axis: the fingers mesh is symmetric about y = 0
    fy = emb.meshes["fingers"].vertices[:, 1]
    assert fy.min() == pytest.approx(-fy.max(), abs=1e-4)
    back = Embodiment.from_dict(json.loads(json.dumps(emb.to_dict())))
    assert back.to_dict() == json.loads(json.dumps(emb.to_dict()))
    flipped = metaworld_sawyer_embodiment(flipped=True)
    np.testing.assert_allclose(
        flipped.cameras["observation.images.corner2"].T_world_cam[:3, :2],
        -corner2.T_world_cam[:3, :2],
        atol=1e-12,
    )
    assert set(EMBODIMENT_PRESETS) >= {"metaworld_sawyer", "metaworld_sawyer_lerobot"}
    lr = load_embodiment("metaworld_sawyer_lerobot")
    assert list(lr.cameras) == ["observation.image"] and lr.cameras["observation.image"].image_size == (
        480,
        480,
    )
    assert lr.ee_pose_dict()["rotation"] == "fixed"
