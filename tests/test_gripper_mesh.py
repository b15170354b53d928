"""lerobot_rnd.gripper_mesh: loaders (files, MJCF, URDF), simplification, the symmetry texture, JSON.

References are independent of the code under test: trimesh's plane slicing and areas, hand-made MJCF / URDF
files with geometry whose EE-frame position is known by construction, our renderer looking at a known box.
"""

import json

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from lerobot_rnd.ee_pose_source import EEPoseSource
from lerobot_rnd.gripper_mesh import GripperMesh, cluster_decimate
from tests.helpers import box_mesh


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


URDF_PRIMITIVES = """<?xml version="1.0"?>
<robot name="p">
  <link name="base"/>
  <link name="ee"><visual><origin xyz="0.1 0 0"/><geometry><cylinder radius="0.01" length="0.04"/></geometry>
  </visual></link>
  <link name="ball"><visual><origin xyz="0 0.1 0"/><geometry><sphere radius="0.015"/></geometry></visual></link>
  <link name="block"><visual><origin xyz="0 0 0.1"/><geometry><box size="0.01 0.02 0.03"/></geometry></visual></link>
  <joint name="mount" type="fixed"><parent link="base"/><child link="ee"/><origin xyz="0 0 0.3"/></joint>
  <joint name="j_ball" type="fixed"><parent link="ee"/><child link="ball"/></joint>
  <joint name="j_block" type="fixed"><parent link="ee"/><child link="block"/></joint>
</robot>
"""


def test_from_urdf_primitives_have_their_urdf_sizes(tmp_path):
    (tmp_path / "p.urdf").write_text(URDF_PRIMITIVES)
    m = GripperMesh.from_urdf(tmp_path / "p.urdf", ["ee", "ball", "block"], ee_link="ee")
    v = m.vertices.astype(np.float64)
    parts = {  # part centre -> expected half extents (URDF cylinders run along z; length is the full length)
        (0.1, 0, 0): (0.01, 0.01, 0.02),
        (0, 0.1, 0): (0.015, 0.015, 0.015),
        (0, 0, 0.1): (0.005, 0.01, 0.015),
    }
    for centre, half in parts.items():
        sel = np.linalg.norm(v - np.array(centre), axis=1) < 0.05
        assert sel.any(), centre
        np.testing.assert_allclose(v[sel].max(0) - centre, half, atol=2e-3)  # polygonised round shapes
        np.testing.assert_allclose(centre - v[sel].min(0), half, atol=2e-3)


def test_cluster_decimate_meets_the_budget_and_keeps_the_shape():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)  # 5120 faces
    rng = np.random.default_rng(0)
    colors = rng.uniform(size=(len(sphere.vertices), 3))
    for search in ("bisect", "grow"):
        v, f, c = cluster_decimate(sphere.vertices, sphere.faces, 500, colors=colors, search=search)
        assert 100 < len(f) <= 500 and c.shape == v.shape
        assert f.min() == 0 and f.max() == len(v) - 1  # no unused vertices
        radius = np.linalg.norm(v, axis=1)
        assert np.all(radius < 0.0501) and np.all(radius > 0.045)  # merged vertices stay near the surface
        assert trimesh.Trimesh(v, f).area == pytest.approx(sphere.area, rel=0.06)
        assert np.all((c >= 0) & (c <= 1))
    v, f, c = cluster_decimate(sphere.vertices, sphere.faces, 10_000)
    assert len(f) == len(sphere.faces) and c is None
    with pytest.raises(ValueError, match="search"):
        cluster_decimate(sphere.vertices, sphere.faces, 100, search="random")
