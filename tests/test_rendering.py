"""Tests of lerobot_rnd.rendering against an independent float64 ray caster (CPU).

The reference below is written independently of the rasteriser: one ray through every
pixel centre (OpenCV K, centres at integer coordinates), Moller-Trumbore against every
triangle, nearest hit with t >= near. CUDA cases are skipped without a GPU.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from lerobot_rnd.rendering import MeshBatch, Rasterizer, RenderOutput, project_points, render

H, W = 48, 64
K_NP = np.array([[70.0, 0.0, 30.3], [0.0, 66.0, 24.6], [0.0, 0.0, 1.0]])


# ------------------------------------------------------------------------ reference


def ray_cast(vertices, faces, T_cam_obj, K, hw, near=1e-3, cull=False):
    """float64 reference. Returns depth (H,W) (inf = miss), face id (H,W) (-1 = miss),
    barycentric coordinates (H,W,3) of the hit (weights of the face's 3 vertices)."""
    h, w = hw
    V = vertices @ T_cam_obj[:3, :3].T + T_cam_obj[:3, 3]
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pix = np.stack([uu.ravel(), vv.ravel(), np.ones(h * w)], -1)
    D = pix @ np.linalg.inv(K).T  # (P,3) rays from the origin, z = 1
    a, b, c = V[faces[:, 0]], V[faces[:, 1]], V[faces[:, 2]]
    e1, e2 = b - a, c - a
    best = np.full(h * w, np.inf)
    fid = np.full(h * w, -1)
    bary = np.zeros((h * w, 3))
    for f0 in range(0, len(faces), 64):
        sl = slice(f0, f0 + 64)
        pvec = np.cross(D[None, :, :], e2[sl, None, :])  # (f,P,3)
        det = (pvec * e1[sl, None, :]).sum(-1)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = -a[sl, None, :]
        uu_ = (tvec * pvec).sum(-1) * inv
        qvec = np.cross(tvec, e1[sl, None, :])
        vv_ = (qvec * D[None]).sum(-1) * inv
        t = (qvec * e2[sl, None, :]).sum(-1) * inv
        hit = ok & (uu_ >= 0) & (vv_ >= 0) & (uu_ + vv_ <= 1) & (t >= near)
        if cull:
            n = np.cross(e1[sl], e2[sl])
            front = (n * a[sl]).sum(-1) < 0  # normal points towards the camera
            hit &= front[:, None]
        t = np.where(hit, t, np.inf)
        j = t.argmin(0)
        tj = t[j, np.arange(t.shape[1])]
        better = tj < best
        best = np.where(better, tj, best)
        fid = np.where(better, j + f0, fid)
        bj = np.stack([1 - uu_ - vv_, uu_, vv_], -1)[j, np.arange(t.shape[1])]
        bary[better] = bj[better]
    # depth along the optical axis: the rays have z = 1
    return best.reshape(h, w), fid.reshape(h, w), bary.reshape(h, w, 3)


# ------------------------------------------------------------------------ helpers


def _pose(rotvec, t):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def _meshes():
    ico = trimesh.creation.icosphere(subdivisions=2, radius=0.06)
    box = trimesh.creation.box(extents=[0.12, 0.05, 0.03])
    cap = trimesh.creation.capsule(height=0.1, radius=0.025, count=[12, 10])
    torus = trimesh.creation.torus(major_radius=0.06, minor_radius=0.018, major_sections=20, minor_sections=10)
    # non-convex "gripper": palm + two fingers (overlapping boxes, self-occluding)
    palm = trimesh.creation.box(extents=[0.10, 0.03, 0.03])
    f1 = trimesh.creation.box(extents=[0.015, 0.02, 0.08], transform=trimesh.transformations.translation_matrix([0.04, 0, 0.05]))
    f2 = trimesh.creation.box(extents=[0.015, 0.02, 0.08], transform=trimesh.transformations.translation_matrix([-0.04, 0, 0.05]))
    grip = trimesh.util.concatenate([palm, f1, f2])
    grip = grip.subdivide()  # more, smaller triangles (some long ones remain)
    return {"ico": ico, "box": box, "capsule": cap, "torus": torus, "gripper": grip}


MESHES = _meshes()


def _render_one(mesh, T, K=K_NP, hw=(H, W), colors=None, **kw):
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, colors)])
    return render(mb, torch.zeros(1, dtype=torch.long), torch.tensor(T)[None], torch.tensor(K), hw, **kw)


def _compare(out: RenderOutput, ref_depth, K=K_NP, n=0, iou_min=0.99):
    mask = out.mask[n].numpy()
    ref_mask = np.isfinite(ref_depth)
    union = (mask | ref_mask).sum()
    iou = (mask & ref_mask).sum() / union if union else 1.0
    assert iou >= iou_min, (iou, mask.sum(), ref_mask.sum())
    both = mask & ref_mask
    pts = out.points_cam[n].numpy()
    if both.any():
        err = np.abs(pts[2][both] - ref_depth[both]).max()
        assert err < 1e-3, err  # < 1 mm
    # off-mask zeros
    assert np.all(pts[:, ~mask] == 0) and np.all(out.rgb[n].numpy()[:, ~mask] == 0)
    if mask.any():
        # the 3-D points project back onto their pixel centres
        p = torch.tensor(pts.reshape(3, -1).T[mask.ravel()]).double()
        uv = project_points(torch.tensor(K), p).numpy()
        vv, uu = np.nonzero(mask)
        assert np.abs(uv - np.stack([uu, vv], -1)).max() < 0.5
    return iou


# ------------------------------------------------------------------------ tests


@pytest.mark.parametrize("name", list(MESHES))
def test_random_poses_match_ray_caster(name):
    mesh = MESHES[name]
    rng = np.random.default_rng(zlib.crc32(name.encode()) % 1000)  # hash() of a str changes per process
    for _ in range(3):
        T = _pose(Rotation.random(random_state=rng.integers(1 << 30)).as_rotvec(), [rng.normal() * 0.03, rng.normal() * 0.03, rng.uniform(0.25, 0.6)])
        out = _render_one(mesh, T)
        depth, _, _ = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W))
        assert np.isfinite(depth).sum() > 20
        _compare(out, depth)


def test_partially_and_fully_off_screen():
    mesh = MESHES["gripper"]
    R = Rotation.from_euler("xyz", [0.3, -0.4, 0.2]).as_rotvec()
    # centre near the left border, bottom-right corner, and entirely off to the side / behind
    for t, expect_empty in [
        ([-0.12, 0.0, 0.3], False),
        ([0.17, 0.13, 0.35], False),
        ([0.0, -0.11, 0.3], False),
        ([1.0, 0.0, 0.3], True),
        ([0.0, 0.0, -0.5], True),
    ]:
        T = _pose(R, t)
        out = _render_one(mesh, T)
        depth, _, _ = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W))
        if expect_empty:
            assert not out.mask.any() and not np.isfinite(depth).any()
        else:
            assert 0 < np.isfinite(depth).sum() < 0.8 * H * W
            # touches the border
            m = out.mask[0].numpy()
            assert m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any()
        _compare(out, depth)


def test_near_plane_crossing_and_camera_inside():
    mesh = MESHES["torus"]
    partial = 0
    for T in [
        _pose([1.2, 0.0, 0.0], [0.0, 0.0, 0.03]),  # torus straddles the camera plane
        _pose([0.0, 0.4, 0.0], [0.06, 0.0, 0.005]),  # camera inside the tube
        _pose([1.57, 0.0, 0.0], [0.0, 0.0, 0.05]),  # the near plane cuts the visible part
    ]:
        for near in (1e-3, 0.02):
            out = _render_one(mesh, T, near=near)
            depth, _, _ = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W), near=near)
            partial += int(0 < np.isfinite(depth).sum() < H * W)
            _compare(out, depth)
            if out.mask.any():
                assert out.points_cam[0, 2][out.mask[0]].min() >= near - 1e-6
    assert partial >= 3


def test_occlusion_nearest_surface_wins():
    near_box = trimesh.creation.box(extents=[0.05, 0.05, 0.01], transform=trimesh.transformations.translation_matrix([0, 0, -0.05]))
    far_box = trimesh.creation.box(extents=[0.15, 0.12, 0.01], transform=trimesh.transformations.translation_matrix([0.01, 0, 0.05]))
    # the far box comes first in the face list, so face order cannot decide the winner
    mesh = trimesh.util.concatenate([far_box, near_box])
    T = _pose([0.05, -0.03, 0.0], [0.0, 0.0, 0.4])
    out = _render_one(mesh, T)
    depth, fid, _ = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W))
    _compare(out, depth)
    z = out.points_cam[0, 2].numpy()
    centre = z[H // 2 - 2 : H // 2 + 2, W // 2 - 2 : W // 2 + 2]
    assert np.all(np.abs(centre - 0.345) < 0.01)  # front face of the near box
    assert (fid >= 12).sum() > 20 and (fid < 12).sum() > 20  # both visible somewhere


def test_projected_vertices_fall_on_the_mask():
    mesh = MESHES["ico"]  # convex: every projected vertex lies inside the silhouette
    rng = np.random.default_rng(3)
    for _ in range(3):
        T = _pose(Rotation.random(random_state=rng.integers(1 << 30)).as_rotvec(), [rng.normal() * 0.02, rng.normal() * 0.02, rng.uniform(0.3, 0.5)])
        out = _render_one(mesh, T)
        m = out.mask[0].numpy()
        pc = mesh.vertices @ T[:3, :3].T + T[:3, 3]
        uv = project_points(torch.tensor(K_NP), torch.tensor(pc)).numpy()
        # vertices well inside the silhouette: normal facing the camera (cos > 0.5)
        nrm = mesh.vertex_normals @ T[:3, :3].T
        facing = (nrm * -pc).sum(-1) / np.linalg.norm(pc, axis=-1) > 0.5
        inside = facing & (uv[:, 0] > 1) & (uv[:, 0] < W - 2) & (uv[:, 1] > 1) & (uv[:, 1] < H - 2)
        assert inside.sum() > 20
        for u, v in uv[inside]:
            u0, v0 = int(np.floor(u)), int(np.floor(v))
            assert m[v0 : v0 + 2, u0 : u0 + 2].any(), (u, v)
        # the silhouette's bounding box matches the projected vertices' one to a pixel
        vv, uu = np.nonzero(m)
        assert abs(uu.min() - np.ceil(uv[:, 0].min())) <= 1 and abs(uu.max() - np.floor(uv[:, 0].max())) <= 1
        assert abs(vv.min() - np.ceil(uv[:, 1].min())) <= 1 and abs(vv.max() - np.floor(uv[:, 1].max())) <= 1


def test_colours_constant_and_perspective_correct_interpolation():
    mesh = MESHES["gripper"]
    T = _pose([0.5, -0.6, 0.3], [0.01, 0.0, 0.3])
    out = _render_one(mesh, T, colors=np.array([0.2, 0.5, 0.9], dtype=np.float32))
    m = out.mask[0]
    assert m.sum() > 200
    rgb = out.rgb[0][:, m]
    assert torch.allclose(rgb, torch.tensor([0.2, 0.5, 0.9])[:, None].expand_as(rgb), atol=1e-6)
    # colours linear in the object-frame position: barycentric interpolation must reproduce
    # the linear function at the (perspective-correct) surface point exactly
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    col = ((mesh.vertices - lo) / (hi - lo)).astype(np.float32)
    out = _render_one(mesh, T, colors=col)
    m = out.mask[0].numpy()
    pc = out.points_cam[0].numpy().reshape(3, -1).T[m.ravel()]
    p_obj = (pc - T[:3, 3]) @ T[:3, :3]
    expect = (p_obj - lo) / (hi - lo)
    got = out.rgb[0].numpy().reshape(3, -1).T[m.ravel()]
    assert np.abs(got - expect).max() < 2e-3
    # and agrees with the reference ray caster's barycentrics
    depth, fid, bary = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W))
    both = m & np.isfinite(depth)
    ref_col = (bary[..., :, None] * col[mesh.faces[np.maximum(fid, 0)]]).sum(-2)
    assert np.abs(out.rgb[0].numpy().transpose(1, 2, 0)[both] - ref_col[both]).max() < 2e-3


def test_backface_culling_convention():
    mesh = MESHES["capsule"]  # closed, outward normals
    T = _pose([0.4, 0.1, -0.2], [0.0, 0.01, 0.35])
    full = _render_one(mesh, T)
    culled = _render_one(mesh, T, cull_backfaces=True)
    assert torch.equal(full.mask, culled.mask)
    assert torch.allclose(full.points_cam, culled.points_cam, atol=1e-6)
    depth_c, _, _ = ray_cast(mesh.vertices, mesh.faces, T, K_NP, (H, W), cull=True)
    _compare(culled, depth_c)
    # reversed winding: everything seen is a back face now
    flipped = _render_one(trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False), T, cull_backfaces=True)
    depth_f, _, _ = ray_cast(mesh.vertices, mesh.faces[:, ::-1], T, K_NP, (H, W), cull=True)
    _compare(flipped, depth_f)
    # (same silhouette for a convex closed mesh, but now the far side is drawn)
    m = full.mask[0] & flipped.mask[0]
    assert m.sum() > 100 and (flipped.points_cam[0, 2][m] > full.points_cam[0, 2][m] + 0.01).float().mean() > 0.9
    # camera inside the closed mesh: no culling sees the inside, culling sees nothing
    T_in = _pose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert _render_one(mesh, T_in).mask.all()
    assert not _render_one(mesh, T_in, cull_backfaces=True).mask.any()


def test_batched_multi_mesh_and_broadcast_K():
    names = ["ico", "box", "torus"]
    mb = MeshBatch.from_meshes([(MESHES[n].vertices, MESHES[n].faces, np.array([i / 3, 0.5, 1 - i / 3])) for i, n in enumerate(names)])
    assert mb.vertices.shape[0] == 3 and mb.face_valid.sum(1).tolist() == [len(MESHES[n].faces) for n in names]
    rng = np.random.default_rng(5)
    idx = [2, 0, 1, 2, 1]
    Ts = [_pose(Rotation.random(random_state=int(rng.integers(1 << 30))).as_rotvec(), [0.0, 0.0, rng.uniform(0.3, 0.5)]) for _ in idx]
    out = render(mb, torch.tensor(idx), torch.tensor(np.stack(Ts)).float(), torch.tensor(K_NP).float(), (H, W))
    assert out.rgb.shape == (5, 3, H, W) and out.mask.shape == (5, H, W) and out.points_cam.shape == (5, 3, H, W)
    assert out.overflow.shape == (5,) and not out.overflow.any()
    for n, (i, T) in enumerate(zip(idx, Ts)):
        depth, _, _ = ray_cast(MESHES[names[i]].vertices, MESHES[names[i]].faces, T, K_NP, (H, W))
        _compare(out, depth, n=n)
        rgb = out.rgb[n][:, out.mask[n]]
        assert torch.allclose(rgb, torch.tensor([i / 3, 0.5, 1 - i / 3]).float()[:, None].expand_as(rgb), atol=1e-6)


def test_static_rasterizer_agrees_with_render_and_reports_overflow():
    mesh = MESHES["gripper"]
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, None)])
    rng = np.random.default_rng(6)
    N = 6
    Ts = np.stack([_pose(Rotation.random(random_state=int(rng.integers(1 << 30))).as_rotvec(), [rng.normal() * 0.02, 0.0, rng.uniform(0.2, 0.4)]) for _ in range(N)])
    Ts[-1] = _pose([1.57, 0.0, 0.0], [0.0, 0.0, 0.04])  # very close: large triangles crossing the near plane
    T = torch.tensor(Ts).float()
    mi = torch.zeros(N, dtype=torch.long)
    K = torch.tensor(K_NP).float()
    ref = render(mb, mi, T, K, (H, W))
    rast = Rasterizer(mb, (H, W))
    rast.calibrate(mi, T, K, margin=1.0)
    out = rast(mi, T, K)  # static path
    assert not out.overflow.any()
    assert torch.equal(out.mask, ref.mask)
    assert torch.allclose(out.points_cam, ref.points_cam, atol=1e-5)
    assert torch.allclose(out.rgb, ref.rgb, atol=1e-5)
    # calling with a preallocated output writes into it
    buf = RenderOutput(torch.full_like(ref.rgb, 7.0), torch.zeros_like(ref.mask), torch.full_like(ref.points_cam, 7.0))
    res = rast(mi, T, K, dynamic=True, out=buf)
    assert res.rgb.data_ptr() == buf.rgb.data_ptr()
    assert torch.equal(buf.mask, ref.mask) and torch.equal(buf.points_cam, ref.points_cam)
    # too small capacities: triangles are dropped and that is reported, per render
    totals = rast.tier_counts(mi, T, K).sum(0).tolist()  # triangles per tier over the N renders
    small = Rasterizer(mb, (H, W), capacity=[0.5 * c / N for c in totals])
    out_s = small(mi, T, K)
    assert out_s.overflow.any()
    lost = (ref.mask & ~out_s.mask).flatten(1).any(1)
    assert torch.all(out_s.overflow[lost])  # every render that lost pixels says so
    # a tier list without large windows flags the close-up render
    no_big = Rasterizer(mb, (H, W), tiers=[(1, 1), (2, 2), (4, 4)])
    assert no_big(mi, T, K).overflow[-1]


def test_float64_inputs_and_shading_flag():
    mesh = MESHES["ico"]
    T = _pose([0.1, 0.2, 0.3], [0.0, 0.0, 0.3])
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, np.array([200, 100, 50], dtype=np.uint8))])
    out = render(mb, torch.zeros(1, dtype=torch.long), torch.tensor(T)[None], torch.tensor(K_NP), (H, W), shading=True)
    m = out.mask[0]
    rgb = out.rgb[0][:, m]
    base = torch.tensor([200, 100, 50]) / 255.0
    ratio = rgb / base[:, None]
    assert (ratio <= 1 + 1e-5).all() and (ratio >= 0.35 - 1e-5).all()
    # the sphere's centre faces the camera: brightest there
    assert ratio[:, :].max() > 0.95
    assert out.rgb.dtype == torch.float32 and out.points_cam.dtype == torch.float32


def test_static_path_traces_as_one_graph():
    """The static path has no host syncs / data-dependent shapes: dynamo traces it whole."""
    mesh = MESHES["ico"]
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, None)])
    N = 3
    T = torch.tensor(np.stack([_pose([0.1 * i, 0.2, 0.0], [0.0, 0.0, 0.3]) for i in range(N)])).float()
    mi = torch.zeros(N, dtype=torch.long)
    K = torch.tensor(K_NP).float()
    rast = Rasterizer(mb, (H, W))
    rast.calibrate(mi, T, K)
    ref = rast(mi, T, K)
    torch._dynamo.reset()
    try:
        fn = torch.compile(lambda a, b, c: rast(a, b, c), backend="eager", fullgraph=True)
        out = fn(mi, T, K)
    finally:
        torch._dynamo.reset()
    assert torch.equal(out.mask, ref.mask) and torch.equal(out.points_cam, ref.points_cam)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_static_path_graph_capture_matches_cpu():
    mesh = MESHES["gripper"]
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, None)])
    rng = np.random.default_rng(7)
    N = 8
    Ts = np.stack([_pose(Rotation.random(random_state=int(rng.integers(1 << 30))).as_rotvec(), [0.0, 0.0, rng.uniform(0.2, 0.4)]) for _ in range(N)])
    T = torch.tensor(Ts).float()
    mi = torch.zeros(N, dtype=torch.long)
    K = torch.tensor(K_NP).float()
    ref = render(mb, mi, T, K, (H, W))
    dev = torch.device("cuda")
    rast = Rasterizer(mb, (H, W), device=dev)
    rast.calibrate(mi, T, K, margin=1.5)
    mi_d, T_d, K_d = mi.to(dev), T.to(dev), K.to(dev)
    out_eager = rast(mi_d, T_d, K_d)
    torch.cuda.synchronize()
    g = torch.cuda.CUDAGraph()
    with torch.cuda.graph(g):
        out_g = rast(mi_d, T_d, K_d)
    g.replay()
    torch.cuda.synchronize()
    for out in (out_eager, out_g):
        assert not out.overflow.any()
        assert torch.equal(out.mask.cpu(), ref.mask)
        assert torch.allclose(out.points_cam.cpu(), ref.points_cam, atol=1e-4)


def test_regression_degenerate_triangle_right_of_the_image_is_not_drawn():
    """A nearly degenerate triangle entirely right of the image once produced an int64-min pixel index."""
    V = torch.tensor([[0.006500000134110451, 0.0681999996304512, -0.04960000142455101], [0.007000000216066837, 0.0681999996304512, -0.05009999871253967], [0.007000000216066837, 0.06907100230455399, -0.04998999834060669]], dtype=torch.float32)
    T = torch.tensor([[[0.22895488142967224, 0.9734323024749756, -0.0030350303277373314, -0.008854784071445465], [-0.9734364748001099, 0.22895674407482147, 0.0002842620015144348, 0.04863381385803223], [0.000971602275967598, 0.0028893272392451763, 0.9999952912330627, 0.10129263997077942], [0.0, 0.0, 0.0, 1.0]]], dtype=torch.float32)
    K = torch.tensor([[[164.5757293701172, 0.0, 63.5], [0.0, 164.5757293701172, 63.5], [0.0, 0.0, 1.0]]], dtype=torch.float32)
    meshes = MeshBatch.from_meshes([(V, torch.tensor([[0, 1, 2]]), None)])
    out = render(meshes, torch.zeros(1, dtype=torch.long), T, K, (128, 128))
    assert not out.mask.any()
    static = Rasterizer(meshes, (128, 128))(torch.zeros(1, dtype=torch.long), T, K)
    assert not static.mask.any() and not static.overflow.any()
