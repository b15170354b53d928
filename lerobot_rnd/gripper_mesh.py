"""Gripper meshes of R&D: triangle meshes in the end-effector frame, their loaders, simplification and the
symmetry-breaking texture.

:class:`GripperMesh` holds vertices (V, 3) float32 [m], faces (F, 3) int64 and per-vertex colours (V, 3) in
[0, 1]. Loaders: MJCF bodies (MuJoCo kinematics), URDF links (pytorch_kinematics) and mesh files (trimesh).
:func:`cluster_decimate` is the package's one mesh decimator (grid vertex clustering), also used for the
Panda scene's visual meshes.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lerobot_rnd.arrays import as_matrix, invert_pose, mujoco_pose, tolist


def _face_components(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """Connected-component label per face (faces sharing a vertex are connected)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return np.zeros(0, dtype=np.int64)
    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    _, vlabel = connected_components(g, directed=False)
    return vlabel[faces[:, 0]]


def _grid_cluster(v: np.ndarray, f: np.ndarray, c: np.ndarray | None, cell: float):
    """One vertex-clustering pass: vertices in the same grid cell (origin at the bounding box minimum, size
    ``cell``) merge into their mean (colours too); degenerate and duplicate faces are dropped (first kept)."""
    keys = np.floor((v - v.min(0)) / cell).astype(np.int64)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    n = inv.max() + 1
    cnt = np.bincount(inv, minlength=n).astype(np.float64)[:, None]
    nv = np.zeros((n, 3))
    np.add.at(nv, inv, v)
    nc = None
    if c is not None:
        nc = np.zeros((n, 3))
        np.add.at(nc, inv, c)
        nc = nc / cnt
    nf = inv[f]
    keep = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
    nf = nf[keep]
    if len(nf):
        _, first = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)
        nf = nf[np.sort(first)]
    return nv / cnt, nf, nc


def cluster_decimate(
    vertices: np.ndarray,
    faces: np.ndarray,
    max_faces: int,
    colors: np.ndarray | None = None,
    search: str = "bisect",
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Grid vertex clustering to at most ``max_faces`` faces (deterministic, NumPy only).

    vertices (V, 3), faces (F, 3), colors (V, 3) or None -> (vertices (V', 3) float64, faces (F', 3),
    colors (V', 3) or None), unused vertices dropped. ``search`` picks the grid cell size: "bisect" (the
    smallest cell that fits, by bisection on a log scale: the most faces within the budget) or "grow" (start
    from the area-based estimate sqrt(2 area / max_faces), grow by 15% until it fits: fewer passes; the
    Panda scene's visual meshes are decimated this way).
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    c = None if colors is None else np.asarray(colors, np.float64)
    if len(f) <= max_faces:
        return v, f, c
    if search == "bisect":
        diag = float(np.linalg.norm(v.max(0) - v.min(0))) or 1.0
        lo, hi = diag * 1e-4, diag
        best = _grid_cluster(v, f, c, hi)
        for _ in range(30):
            mid = math.sqrt(lo * hi)
            res = _grid_cluster(v, f, c, mid)
            if len(res[1]) <= max_faces:
                best, hi = res, mid
            else:
                lo = mid
            if hi / lo < 1.02:
                break
    elif search == "grow":
        e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()
        cell = math.sqrt(2.0 * area / max_faces)
        for _ in range(60):
            best = _grid_cluster(v, f, c, cell)
            if len(best[1]) <= max_faces:
                break
            cell *= 1.15
    else:
        raise ValueError(f"search must be 'bisect' or 'grow', got {search!r}")
    nv, nf, nc = best
    used = np.unique(nf)
    remap = -np.ones(len(nv), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return nv[used], remap[nf], None if nc is None else nc[used]


def _quadric_simplify(v: np.ndarray, f: np.ndarray, c: np.ndarray, max_faces: int):
    import trimesh
    from scipy.spatial import cKDTree

    m = trimesh.Trimesh(v, f, process=False)
    s = m.simplify_quadric_decimation(face_count=int(max_faces))
    sv, sf = np.asarray(s.vertices), np.asarray(s.faces)
    _, idx = cKDTree(v).query(sv)
    return sv, sf, c[idx]


def _has_fast_simplification() -> bool:
    try:
        import fast_simplification  # noqa: F401
    except ImportError:
        return False
    return True


def _primitive_trimesh(gtype: str, size: np.ndarray):
    import trimesh

    if gtype == "box":
        return trimesh.creation.box(extents=2.0 * size[:3])
    if gtype == "sphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=float(size[0]))
    if gtype == "ellipsoid":
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.vertices = m.vertices * size[:3][None]
        return m
    if gtype == "cylinder":
        return trimesh.creation.cylinder(radius=float(size[0]), height=2.0 * float(size[1]), sections=24)
    if gtype == "capsule":
        return trimesh.creation.capsule(height=2.0 * float(size[1]), radius=float(size[0]), count=[12, 12])
    raise ValueError(f"unsupported primitive type {gtype}")


def _urdf_half_sizes(gtype: str, param) -> np.ndarray:
    """A URDF primitive's parameters (box extents, sphere radius, cylinder / capsule (radius, length)) as the
    MJCF half sizes :func:`_primitive_trimesh` takes."""
    if gtype == "box":
        return np.asarray(param, dtype=np.float64) / 2.0
    if gtype == "sphere":
        return np.array([float(param)])
    r, length = param
    return np.array([float(r), float(length) / 2.0])


@dataclass
class GripperMesh:
    """Triangle mesh in the EE frame: vertices (V,3) float32 [m], faces (F,3) int64, colours (V,3) in [0,1]."""

    vertices: Any
    faces: Any
    vertex_colors: Any = None
    name: str = ""

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float32)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"mesh '{self.name}': vertices must have shape (V, 3), got {v.shape}")
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"mesh '{self.name}': faces must have shape (F, 3), got {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"mesh '{self.name}': face indices out of range [0, {len(v)})")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"mesh '{self.name}': non-finite vertices")
        if self.vertex_colors is None:
            c = np.full((len(v), 3), 0.5, dtype=np.float32)
        else:
            c = np.asarray(self.vertex_colors, dtype=np.float32)
            if c.ndim == 1 and c.shape[0] in (3, 4):
                c = np.broadcast_to(c[:3], (len(v), 3)).copy()
            if c.ndim != 2 or c.shape[0] != len(v) or c.shape[1] not in (3, 4):
                raise ValueError(f"mesh '{self.name}': vertex_colors must have shape (V, 3), got {c.shape}")
            c = c[:, :3]
            if c.max(initial=0.0) > 1.0 + 1e-6:  # 0..255 colours
                c = c / 255.0
        self.vertices, self.faces, self.vertex_colors = v, f, np.clip(c, 0.0, 1.0).astype(np.float32)

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    def bounds(self) -> np.ndarray:
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    # ------------------------------------------------------------------ combination
    @staticmethod
    def concatenate(meshes: Sequence[GripperMesh], name: str = "") -> GripperMesh:
        if not meshes:
            raise ValueError("no meshes to concatenate")
        vs, fs, cs, off = [], [], [], 0
        for m in meshes:
            vs.append(m.vertices)
            fs.append(m.faces + off)
            cs.append(m.vertex_colors)
            off += len(m.vertices)
        return GripperMesh(np.concatenate(vs), np.concatenate(fs), np.concatenate(cs), name)

    def transformed(self, T: Any) -> GripperMesh:
        """The mesh with its vertices mapped by the rigid (or any affine) 4x4 transform ``T``."""
        T = as_matrix(T, (4, 4), "T")
        v = self.vertices.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        return GripperMesh(v, self.faces.copy(), self.vertex_colors.copy(), self.name)

    # ------------------------------------------------------------------ loaders
    @classmethod
    def from_trimesh(cls, mesh, color: Sequence[float] | None = None, name: str = "") -> GripperMesh:
        v = np.asarray(mesh.vertices)
        f = np.asarray(mesh.faces)
        if color is not None:
            c = np.broadcast_to(np.asarray(color, dtype=np.float64)[:3], (len(v), 3))
        else:
            c = None
            try:
                vc = np.asarray(mesh.visual.vertex_colors)
                if vc.shape[0] == len(v):
                    c = vc[:, :3] / 255.0
            except Exception:  # noqa: BLE001  (textured / no colour)
                c = None
        return cls(v, f, c, name)

    @classmethod
    def from_files(
        cls,
        paths: Sequence[str | os.PathLike],
        transforms: Sequence[Any] | None = None,
        colors: Sequence[Sequence[float]] | None = None,
        name: str = "",
    ) -> GripperMesh:
        """OBJ / STL / PLY files (one mesh each), each mapped by its 4x4 ``T_ee_file`` into the EE frame."""
        import trimesh

        paths = list(paths)
        if transforms is not None and len(transforms) != len(paths):
            raise ValueError(f"{len(transforms)} transforms for {len(paths)} mesh files")
        if colors is not None and len(colors) != len(paths):
            raise ValueError(f"{len(colors)} colours for {len(paths)} mesh files")
        parts = []
        for i, p in enumerate(paths):
            if not Path(p).exists():
                raise FileNotFoundError(f"mesh file not found: {p}")
            tm = trimesh.load(str(p), force="mesh", process=False)
            m = cls.from_trimesh(tm, None if colors is None else colors[i])
            if transforms is not None and transforms[i] is not None:
                m = m.transformed(transforms[i])
            parts.append(m)
        return cls.concatenate(parts, name)

    @classmethod
    def from_mjcf_body(
        cls,
        model,
        body_name: str,
        T_ee_body: Any | None = None,
        include_children: bool = True,
        geom_group: Sequence[int] | None = None,
        ee_body: str | None = None,
        ee_site: str | None = None,
        qpos: Mapping[str, float] | np.ndarray | None = None,
        exclude_bodies: Sequence[str] = (),
        name: str = "",
    ) -> GripperMesh:
        """Every visual geom of ``body_name`` (and its subtree) as one mesh in the EE frame.

        ``model``: ``mujoco.MjModel`` or an MJCF path. Mesh geoms and primitives (box, sphere,
        capsule, cylinder, ellipsoid) are collected with their world poses from ``mj_forward`` at
        ``qpos`` (default ``model.qpos0``; a dict sets named joints on top of qpos0, e.g. the gripper
        open). The EE frame is ``ee_site`` or ``ee_body`` (default: ``body_name``), or, when
        ``T_ee_body`` is given, the body frame mapped by that transform. ``geom_group``: groups to
        keep (default 0, 1, 2: those MuJoCo renders by default); fully transparent geoms are skipped.
        """
        import mujoco

        if isinstance(model, (str, os.PathLike)):
            model = mujoco.MjModel.from_xml_path(str(model))
        data = mujoco.MjData(model)
        if qpos is None:
            data.qpos[:] = model.qpos0
        elif isinstance(qpos, Mapping):
            data.qpos[:] = model.qpos0
            for jname, val in qpos.items():
                jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, jname)
                if jid < 0:
                    raise ValueError(f"MuJoCo model has no joint '{jname}'")
                data.qpos[model.jnt_qposadr[jid]] = val
        else:
            q = np.asarray(qpos, dtype=np.float64)
            if q.shape != (model.nq,):
                raise ValueError(f"qpos must have shape ({model.nq},), got {q.shape}")
            data.qpos[:] = q
        mujoco.mj_forward(model, data)

        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
        if bid < 0:
            names = [model.body(i).name for i in range(model.nbody)]
            raise ValueError(f"MuJoCo model has no body '{body_name}'; bodies: {names}")
        excluded = set()
        for b in exclude_bodies:
            eid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, b)
            if eid < 0:
                raise ValueError(f"MuJoCo model has no body '{b}'")
            excluded.add(eid)
        bodies = {bid}
        if include_children:
            changed = True
            while changed:
                changed = False
                for b in range(model.nbody):
                    if b not in bodies and int(model.body_parentid[b]) in bodies and b != 0:
                        bodies.add(b)
                        changed = True
        # drop excluded bodies and their subtrees
        if excluded:
            changed = True
            while changed:
                changed = False
                for b in bodies:
                    if int(model.body_parentid[b]) in excluded and b not in excluded:
                        excluded.add(b)
                        changed = True
            bodies -= excluded

        T_world_body = mujoco_pose(data.xmat[bid], data.xpos[bid])
        if T_ee_body is not None:
            T_ee_world = as_matrix(T_ee_body, (4, 4), "T_ee_body") @ invert_pose(T_world_body)
        elif ee_site is not None:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, ee_site)
            if sid < 0:
                raise ValueError(f"MuJoCo model has no site '{ee_site}'")
            T_ee_world = invert_pose(mujoco_pose(data.site_xmat[sid], data.site_xpos[sid]))
        else:
            eb = body_name if ee_body is None else ee_body
            eid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, eb)
            if eid < 0:
                raise ValueError(f"MuJoCo model has no body '{eb}'")
            T_ee_world = invert_pose(mujoco_pose(data.xmat[eid], data.xpos[eid]))

        groups = (0, 1, 2) if geom_group is None else tuple(int(g) for g in geom_group)
        type_names = {
            int(mujoco.mjtGeom.mjGEOM_BOX): "box",
            int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
            int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
            int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
            int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
        }
        default_rgba = np.array([0.5, 0.5, 0.5, 1.0])
        parts = []
        for g in range(model.ngeom):
            if int(model.geom_bodyid[g]) not in bodies or int(model.geom_group[g]) not in groups:
                continue
            rgba = np.asarray(model.geom_rgba[g], dtype=np.float64)
            matid = int(model.geom_matid[g])
            if matid >= 0 and np.allclose(rgba, default_rgba):
                rgba = np.asarray(model.mat_rgba[matid], dtype=np.float64)
            if rgba[3] <= 0.0:
                continue
            gtype = int(model.geom_type[g])
            if gtype == int(mujoco.mjtGeom.mjGEOM_MESH):
                mid = int(model.geom_dataid[g])
                va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
                fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
                v = np.asarray(model.mesh_vert[va : va + vn], dtype=np.float64)
                f = np.asarray(model.mesh_face[fa : fa + fn], dtype=np.int64)
            elif gtype in type_names:
                tm = _primitive_trimesh(type_names[gtype], np.asarray(model.geom_size[g], dtype=np.float64))
                v, f = np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64)
            else:  # planes, height fields, SDFs: not part of a gripper
                warnings.warn(f"geom {model.geom(g).name!r} of type {gtype} skipped", stacklevel=2)
                continue
            T_world_geom = mujoco_pose(data.geom_xmat[g], data.geom_xpos[g])
            T = T_ee_world @ T_world_geom
            parts.append(GripperMesh(v @ T[:3, :3].T + T[:3, 3], f, np.broadcast_to(rgba[:3], (len(v), 3))))
        if not parts:
            raise ValueError(f"no visible geoms in body '{body_name}' (groups {groups})")
        return cls.concatenate(parts, name or body_name)

    @classmethod
    def from_urdf(
        cls,
        urdf_path: str | os.PathLike,
        link_names: Sequence[str],
        ee_link: str,
        joint_values: Mapping[str, float] | None = None,
        T_link_ee: Any | None = None,
        mesh_dirs: Sequence[str | os.PathLike] = (),
        name: str = "",
    ) -> GripperMesh:
        """Visual geometry of URDF links in the frame of ``ee_link`` (forward kinematics by pytorch_kinematics).

        ``joint_values``: named joint positions (others 0), e.g. the gripper open. ``T_link_ee``: pose
        of the EE frame in ``ee_link`` (default identity). Mesh filenames (``package://`` stripped) are
        looked up relative to the URDF folder and ``mesh_dirs``.
        """
        import pytorch_kinematics as pk
        import trimesh

        urdf_path = Path(urdf_path)
        xml = urdf_path.read_bytes()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            chain = pk.build_chain_from_urdf(xml).to(dtype=torch.float64)
        joint_names = chain.get_joint_parameter_names()
        q = torch.zeros(1, len(joint_names), dtype=torch.float64)
        for jn, val in (joint_values or {}).items():
            if jn not in joint_names:
                raise ValueError(f"URDF has no movable joint '{jn}'; joints: {joint_names}")
            q[0, joint_names.index(jn)] = float(val)
        fk = chain.forward_kinematics(q)  # q is (1, 0) float64 for a chain without movable joints
        link_names_all = chain.get_link_names()
        for ln in list(link_names) + [ee_link]:
            if ln not in link_names_all:
                raise ValueError(f"URDF has no link '{ln}'; links: {link_names_all}")

        def world_of(link: str) -> np.ndarray:
            return fk[link].get_matrix()[0].detach().cpu().numpy().astype(np.float64)

        T_ee_link_world = invert_pose(world_of(ee_link))
        if T_link_ee is not None:
            T_ee_link_world = invert_pose(as_matrix(T_link_ee, (4, 4), "T_link_ee")) @ T_ee_link_world
        search = [urdf_path.parent, *[Path(d) for d in mesh_dirs]]

        def resolve(fname: str) -> Path:
            fn = fname
            for prefix in ("package://", "file://"):
                fn = fn.removeprefix(prefix)
            cand = [Path(fn)] if Path(fn).is_absolute() else []
            parts = Path(fn).parts
            for base in search:
                for k in range(len(parts)):
                    cand.append(base.joinpath(*parts[k:]))
            for c in cand:
                if c.exists():
                    return c
            raise FileNotFoundError(f"URDF mesh '{fname}' not found under {[str(s) for s in search]}")

        meshes = []
        for ln in link_names:
            link = chain.find_link(ln)
            T_w_link = world_of(ln)
            for vis in link.visuals:
                if vis.geom_type is None:
                    continue
                T_link_vis = np.eye(4) if vis.offset is None else vis.offset.get_matrix()[0].cpu().numpy()
                if vis.geom_type == "mesh":
                    fname, scale = vis.geom_param
                    tm = trimesh.load(str(resolve(fname)), force="mesh", process=False)
                    if scale is not None:
                        tm.apply_scale(np.asarray(scale, dtype=np.float64))
                elif vis.geom_type in ("box", "cylinder", "sphere", "capsule"):
                    tm = _primitive_trimesh(vis.geom_type, _urdf_half_sizes(vis.geom_type, vis.geom_param))
                else:
                    continue
                m = cls.from_trimesh(tm)
                meshes.append(m.transformed(T_ee_link_world @ T_w_link @ T_link_vis))
        if not meshes:
            raise ValueError(f"no visual geometry in URDF links {list(link_names)}")
        return cls.concatenate(meshes, name)

    # ------------------------------------------------------------------ processing
    def simplified(self, max_faces: int, method: str = "auto", keep_small_parts: int = 256) -> GripperMesh:
        """A copy with at most ``max_faces`` faces.

        Connected parts with at most ``keep_small_parts`` faces (boxes, fingers pads...) are kept
        exactly; the remaining budget is shared among the larger parts in proportion to their size.
        ``method``: "quadric" (trimesh + fast_simplification), "cluster" (grid vertex clustering, no
        extra dependency) or "auto" (quadric when fast_simplification is importable).
        """
        if self.num_faces <= max_faces:
            return GripperMesh(self.vertices.copy(), self.faces.copy(), self.vertex_colors.copy(), self.name)
        if method == "auto":
            method = "quadric" if _has_fast_simplification() else "cluster"
        if method not in ("quadric", "cluster"):
            raise ValueError(f"unknown simplification method {method!r}")
        comp = _face_components(self.num_vertices, self.faces)
        labels, counts = np.unique(comp, return_counts=True)
        small = counts <= keep_small_parts
        budget = max_faces - int(counts[small].sum())
        if budget < 4 * int((~small).sum()):
            raise ValueError(
                f"max_faces={max_faces} is too small: {int(counts[small].sum())} faces are in small parts"
            )
        big_total = int(counts[~small].sum())
        parts = []
        for lab, cnt, is_small in zip(labels, counts, small, strict=True):
            fsel = self.faces[comp == lab]
            used = np.unique(fsel)
            remap = np.zeros(self.num_vertices, dtype=np.int64)
            remap[used] = np.arange(len(used))
            v, f, c = self.vertices[used].astype(np.float64), remap[fsel], self.vertex_colors[used]
            if not is_small:
                target = max(4, int(budget * cnt / big_total))
                if cnt > target:
                    if method == "quadric":
                        v, f, c = _quadric_simplify(v, f, c, target)
                    if len(f) > target:  # grid clustering, or quadric decimation overshot slightly
                        v, f, c = cluster_decimate(v, f, target, colors=c)
            if len(f):
                parts.append(GripperMesh(v, f, c))
        return GripperMesh.concatenate(parts, self.name)

    def with_symmetry_texture(
        self,
        axis: int = 1,
        colors: Sequence[Sequence[float]] = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ) -> GripperMesh:
        """Symmetry-breaking texture: ``colors[0]`` where the EE-frame coordinate ``axis`` is >= 0,
        ``colors[1]`` where it is < 0.

        Faces straddling the plane are cut along it and the cut vertices duplicated, so the colour
        boundary is exactly the plane (no colour interpolation across it).
        """
        if axis not in (0, 1, 2):
            raise ValueError(f"axis must be 0, 1 or 2, got {axis}")
        if len(colors) != 2:
            raise ValueError("colors must be two RGB triples (side >= 0, side < 0)")
        sides = []
        for sign, col in ((1.0, colors[0]), (-1.0, colors[1])):
            v, f = _clip_halfspace(self.vertices.astype(np.float64), self.faces, axis, sign)
            if len(f):
                sides.append(GripperMesh(v, f, np.broadcast_to(np.asarray(col, np.float64)[:3], (len(v), 3))))
        return GripperMesh.concatenate(sides, self.name)

    def without_texture(self, color: Sequence[float] = (0.5, 0.5, 0.5)) -> GripperMesh:
        c = np.broadcast_to(np.asarray(color, dtype=np.float32)[:3], (self.num_vertices, 3)).copy()
        return GripperMesh(self.vertices.copy(), self.faces.copy(), c, self.name)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, decimals: int = 6) -> dict[str, Any]:
        return {
            "name": self.name,
            "vertices": tolist(self.vertices, decimals),
            "faces": self.faces.tolist(),
            "vertex_colors": tolist(self.vertex_colors, 4),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GripperMesh:
        unknown = sorted(set(d) - {"vertices", "faces", "vertex_colors", "name"})
        if unknown:
            raise ValueError(f"mesh {d.get('name', '?')!r}: unknown keys {unknown}; keys: vertices, faces, vertex_colors, name")
        for req in ("vertices", "faces"):
            if req not in d:
                raise ValueError(f"mesh {d.get('name', '?')!r}: missing '{req}'")
        return cls(
            np.asarray(d["vertices"], dtype=np.float32).reshape(-1, 3),
            np.asarray(d["faces"], dtype=np.int64).reshape(-1, 3),
            None
            if d.get("vertex_colors") is None
            else np.asarray(d["vertex_colors"], np.float32).reshape(-1, 3),
            d.get("name", ""),
        )

    def to_trimesh(self):
        import trimesh

        colors = np.concatenate(
            [np.round(self.vertex_colors * 255), np.full((self.num_vertices, 1), 255)], axis=1
        ).astype(np.uint8)
        return trimesh.Trimesh(self.vertices, self.faces, vertex_colors=colors, process=False)


def _clip_halfspace(v: np.ndarray, f: np.ndarray, axis: int, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Part of the mesh where sign * v[:, axis] >= 0 (side +) or > 0 (side -), cut exactly at the plane."""
    d = sign * v[:, axis]
    inside = d >= 0.0 if sign > 0 else d > 0.0
    new_v: list[np.ndarray] = [v]
    edge_vertex: dict[tuple[int, int], int] = {}
    n = len(v)

    def cut(a: int, b: int) -> int:
        nonlocal n
        key = (a, b) if a < b else (b, a)
        idx = edge_vertex.get(key)
        if idx is None:
            ta = d[a] / (d[a] - d[b])
            p = v[a] + (v[b] - v[a]) * ta
            p[axis] = 0.0
            new_v.append(p[None])
            idx = edge_vertex[key] = n
            n += 1
        return idx

    ins = inside[f]
    cnt = ins.sum(1)
    out_faces = [f[cnt == 3]]
    extra = []
    for fi in np.nonzero((cnt == 1) | (cnt == 2))[0]:
        tri, flags = f[fi], ins[fi]
        if cnt[fi] == 1:
            k = int(np.argmax(flags))  # the inside vertex
            a, b, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            extra.append((a, cut(a, b), cut(c, a)))
        else:
            k = int(np.argmin(flags))  # the outside vertex
            o, b, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            x_ob, x_co = cut(o, b), cut(c, o)
            extra.append((x_ob, b, c))
            extra.append((x_ob, c, x_co))
    if extra:
        out_faces.append(np.asarray(extra, dtype=np.int64))
    faces = np.concatenate(out_faces).astype(np.int64)
    verts = np.concatenate(new_v)
    if len(faces):
        tri = verts[faces]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        faces = faces[area2 > 1e-14]
    used = np.unique(faces)
    remap = -np.ones(len(verts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces].reshape(-1, 3)
