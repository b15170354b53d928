"""Utilities shared by the test modules: tiny policy configs, policy and batch builders, the GL probe and the
backward-compatibility procedures. Test modules import from here, never from each other."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import trimesh
from scipy.spatial.transform import Rotation

from lerobot_rnd.embodiment import CameraCalibration, EEPoseSource, Embodiment, GripperMesh

REPO_ROOT = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).resolve().parent / "fixtures"

TINY_POLICY_KWARGS = dict(
    device="cpu",
    dim_model=64,
    n_layers=2,
    n_heads=4,
    patch_size=16,
    image_size=(64, 64),
    chunk_size=4,
    n_action_steps=2,
    num_train_timesteps=20,
    stats_num_samples=32,
)


class StandInNetwork(torch.nn.Module):
    """Base of the tests' stand-ins for `RnDDenoiser`: no observation tokens to cache (`embed_observation` gives
    None, so the sampler passes `obs_tokens=None`); subclasses define `forward` with the denoiser's arguments."""

    def embed_observation(self, obs_rgb, obs_points):
        return None


def tiny_policy_flags() -> list[str]:
    """`TINY_POLICY_KWARGS` as lerobot-train flags (the device is passed separately)."""
    def value(v):
        return "[" + ",".join(str(x) for x in v) + "]" if isinstance(v, tuple) else str(v)

    return [f"--policy.{k}={value(v)}" for k, v in TINY_POLICY_KWARGS.items() if k != "device"]


def make_policy(root, features: dict | None = None, with_dataset_meta: bool = True, **overrides):
    """An `RnDPolicy` (TINY_POLICY_KWARGS + overrides) on the toy dataset at `root` -> (policy, meta).

    `features`: policy features to use instead of (or, for new keys, next to) the dataset's;
    `with_dataset_meta=False` builds it without the dataset (no embodiment file, no statistics)."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    all_features = {**dataset_to_policy_features(meta.features), **(features or {})}
    cfg = RnDConfig(**{**TINY_POLICY_KWARGS, **overrides})
    cfg.output_features = {k: f for k, f in all_features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in all_features.items() if k not in cfg.output_features}
    return RnDPolicy(cfg, dataset_meta=meta if with_dataset_meta else None), meta


def dataset_items(root, cfg, indices=None) -> dict[str, torch.Tensor]:
    """The toy dataset's training samples for `cfg`'s history / horizon, stacked: {key: (N, ...)}.

    `indices`: which frames (default all)."""
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    ds = LeRobotDataset("local/toy_reach", root=root, delta_timestamps=resolve_delta_timestamps(cfg, meta))
    items = [ds[i] for i in (range(len(ds)) if indices is None else indices)]
    keys = [k for k in items[0] if isinstance(items[0][k], torch.Tensor)]
    return {k: torch.stack([it[k] for it in items]) for k in keys}


def training_batch(root, cfg, n=4) -> dict[str, torch.Tensor]:
    """`n` evenly spaced training samples of the toy dataset."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    total = LeRobotDatasetMetadata("local/toy_reach", root=root).total_frames
    return dataset_items(root, cfg, list(range(0, total, max(1, total // n)))[:n])


# --------------------------------------------------------------------------------------------------
# Embodiment pieces
# --------------------------------------------------------------------------------------------------
def random_pose(rng, trans_scale=0.5) -> np.ndarray:
    """A random rigid 4x4 transform (scipy's uniform rotation, translation in +-trans_scale)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-trans_scale, trans_scale, 3)
    return T


def simple_camera(H=96, W=128, static=True, **kw) -> CameraCalibration:
    """A camera 1 m behind the origin looking along +z, static or (``static=False``) mounted on the EE."""
    K = [[100.0, 0.0, 60.3], [0.0, 105.0, 47.1], [0.0, 0.0, 1.0]]
    T = np.eye(4)
    T[:3, 3] = (0.1, -0.2, -1.0)
    if static:
        return CameraCalibration("cam", K, (H, W), T_world_cam=T, **kw)
    return CameraCalibration("cam", K, (H, W), T_ee_cam=T, **kw)


def points_in_front(cam: CameraCalibration, rng, n=20) -> np.ndarray:
    """n world points (n, 3) 0.8-1.5 m in front of a static camera, within +-0.3 m of its optical axis."""
    p_cam = np.concatenate([rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(0.8, 1.5, (n, 1))], 1)
    return cam.T_world_cam[:3, 3] + (cam.T_world_cam[:3, :3] @ p_cam.T).T


def box_mesh(center=(0, 0, 0), extents=(0.02, 0.04, 0.06), color=(0.5, 0.5, 0.5)) -> GripperMesh:
    b = trimesh.creation.box(extents=extents)
    b.apply_translation(center)
    return GripperMesh.from_trimesh(b, color=color)


def small_embodiment() -> Embodiment:
    """Two cameras (static front, EE-mounted wrist), box meshes, an 8-D quat_wxyz state."""
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


# --------------------------------------------------------------------------------------------------
# Simulators
# --------------------------------------------------------------------------------------------------
def gl_available() -> bool:
    """Whether MuJoCo can render offscreen here (MUJOCO_GL=egl / osmesa on a headless machine)."""
    try:
        import mujoco
    except ImportError:
        return False
    try:
        m = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
        r = mujoco.Renderer(m, 8, 8)
        r.render()
        r.close()
        return True
    except Exception:  # noqa: BLE001
        return False


MARKER_OBJID = 1000  # segmentation object ids of the marker spheres: MARKER_OBJID + i


def mujoco_segmentation(env, camera, size, markers=(), radii=(), markers_only=False, only_geoms=None):
    """MuJoCo's segmentation image (H, W, 2) = (objid, objtype) of an env camera, with marker spheres drawn as
    objid MARKER_OBJID + i (type site); flipped like the env's images.

    ``markers_only``: the model's geoms are dropped (nothing occludes the markers); ``only_geoms``: only these
    geoms are drawn (no occlusion by the arm or the sites)."""
    import mujoco

    site = int(mujoco.mjtObj.mjOBJ_SITE)
    r = mujoco.Renderer(env.model, size[0], size[1])
    r.enable_segmentation_rendering()
    opt = mujoco.MjvOption()
    saved = env.model.geom_group.copy()
    if only_geoms is not None:
        env.model.geom_group[:] = 0
        env.model.geom_group[only_geoms] = 5
        opt.geomgroup[:] = 0
        opt.geomgroup[5] = 1
        opt.sitegroup[:] = 0
    try:
        r.update_scene(env.data, camera=env.mujoco_camera_name(camera), scene_option=opt)
    finally:
        env.model.geom_group[:] = saved
    if markers_only:
        r.scene.ngeom = 0
    for i, (p, rad) in enumerate(zip(markers, radii, strict=True)):
        g = r.scene.geoms[r.scene.ngeom]
        mujoco.mjv_initGeom(
            g, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([rad, 0, 0]), np.asarray(p, float), np.eye(3).ravel(),
            np.ones(4, np.float32),
        )  # fmt: skip
        g.objtype, g.objid, g.segid = site, MARKER_OBJID + i, r.scene.ngeom
        r.scene.ngeom += 1
    seg = r.render().copy()
    r.close()
    if camera in env.flip_cameras:
        seg = seg[::-1, ::-1]
    return seg


def marker_errors(env, cam, size, seed=0, depth_range=(0.3, 1.5), extra_points=()) -> np.ndarray:
    """Pixel errors (N, 2) between the centroids of marker spheres as MuJoCo draws them in ``env`` and our
    calibration ``cam``'s projection of their centres. 16 markers sit on a 4x4 grid of pixels at random depths
    in ``depth_range`` (m), plus ``extra_points`` (world); markers off screen, hidden or overlapping another
    are skipped."""
    import mujoco

    site = int(mujoco.mjtObj.mjOBJ_SITE)
    rng = np.random.default_rng(seed)
    T_we = torch.tensor(env.ee_pose())
    H, W = size
    gu, gv = np.meshgrid(np.linspace(0.15, 0.85, 4) * (W - 1), np.linspace(0.15, 0.85, 4) * (H - 1))
    jitter = np.c_[rng.uniform(-2, 2, (16, 2)), np.zeros(16)]
    uv1 = np.stack([gu.ravel(), gv.ravel(), np.ones(16)], 1) + jitter
    depth = rng.uniform(*depth_range, 16)
    p_cam = (np.linalg.inv(cam.K) @ uv1.T).T * depth[:, None]
    T_wc = cam.T_world_cam_at(T_we).numpy()
    pts = np.concatenate([p_cam @ T_wc[:3, :3].T + T_wc[:3, 3], np.reshape(extra_points, (-1, 3))])
    uv, z = cam.project(torch.tensor(pts), T_we)
    radii = 5.0 * z.numpy() / cam.K[1, 1]  # about 5 px on screen
    seg = mujoco_segmentation(env, cam.name, size, pts, radii, markers_only=True)
    errs = []
    for i in range(len(pts)):
        others = np.delete(uv.numpy(), i, axis=0)
        if np.linalg.norm(others - uv[i].numpy(), axis=1).min() < 12:  # overlaps another marker
            continue
        m = (seg[..., 0] == MARKER_OBJID + i) & (seg[..., 1] == site)
        if m.sum() < 0.9 * np.pi * 25:  # off screen or behind another marker
            continue
        vv, uu = np.nonzero(m)
        errs.append([uu.mean() - uv[i, 0].item(), vv.mean() - uv[i, 1].item()])
    return np.asarray(errs)


def subtree_geoms(model, roots, max_group: int | None = 2) -> list[int]:
    """Geoms of the bodies ``roots`` and their subtrees (only groups <= ``max_group``, which MuJoCo draws by
    default)."""
    ids = {model.body(r).id for r in roots}
    out = []
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        while b > 0 and b not in ids:
            b = int(model.body_parentid[b])
        if b in ids and (max_group is None or int(model.geom_group[g]) <= max_group):
            out.append(g)
    return out


def gripper_mask_iou(env, emb, key, geoms, size=None) -> tuple[float, int]:
    """IoU of our renderer's mask of ``emb``'s mesh for camera ``key`` (at the EE pose read from the env's
    state, as the policy reads it) with MuJoCo's segmentation of ``geoms`` drawn alone; and the number of
    MuJoCo's gripper pixels. ``size``: render both at this (H, W) instead of the calibration's."""
    import mujoco

    from lerobot_rnd.geometry import invert_transform
    from lerobot_rnd.rendering import render

    cam = emb.cameras[key] if size is None else emb.cameras[key].resized(*size)
    seg = mujoco_segmentation(env, cam.name, cam.image_size, only_geoms=geoms)  # no occlusion by the arm
    gt = np.isin(seg[..., 0], geoms) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))
    T_we = emb.ee_pose_source.ee_pose(torch.as_tensor(env.state(), dtype=torch.float64))
    T_ce = invert_transform(cam.T_world_cam_at(T_we)) @ T_we
    out = render(emb.mesh_batch(), torch.tensor([emb.mesh_index(key)]), T_ce[None].float(),
                 cam.K_tensor()[None], cam.image_size)  # fmt: skip
    pm = out.mask[0].numpy()
    return float((gt & pm).sum() / (gt | pm).sum()), int(gt.sum())


# --------------------------------------------------------------------------------------------------
# Backward compatibility: a checkpoint and training losses recorded before the issue-10 refactor
# (tests/fixtures/make_backward_compat_fixtures.py), checked by tests/test_backward_compat.py.
# --------------------------------------------------------------------------------------------------
FIXTURE_CHECKPOINT = FIXTURES / "rnd_tiny_checkpoint"
FIXTURE_EXPECTED_ACTIONS = FIXTURES / "rnd_tiny_expected_actions.safetensors"
FIXTURE_TRAINING_LOSSES = FIXTURES / "rnd_tiny_training_losses.json"
#: frozen (not derived from TINY_POLICY_KWARGS): the recorded fixtures depend on it
FIXTURE_POLICY_KWARGS = dict(
    device="cpu",
    variant="AI",
    dim_model=32,
    n_layers=1,
    n_heads=2,
    patch_size=16,
    image_size=(64, 64),
    chunk_size=4,
    n_action_steps=2,
    num_train_timesteps=20,
    stats_num_samples=32,
)
LOSS_STEPS = 20


def fixture_inference_inputs() -> dict[str, torch.Tensor]:
    """Fixed observations with history (B=2, H=2; 32x32 images, which the policy resizes) and DDIM noise
    (B, chunk_size=4, 6) for the fixture policy."""
    g = torch.Generator().manual_seed(10)
    return {
        "observation.images.front": torch.rand(2, 2, 3, 32, 32, generator=g),
        "observation.images.wrist": torch.rand(2, 2, 3, 32, 32, generator=g),
        "observation.state": torch.tensor([[0.02, -0.01, 0.2, 1.0], [0.03, 0.0, 0.19, 1.0]])[None]
        .expand(2, 2, 4)
        .clone(),
        "noise": torch.randn(2, 4, 6, generator=g),
    }


def record_training_losses(root, steps: int = LOSS_STEPS) -> list[dict[str, float]]:
    """Train the fixture-size R&D-AI from scratch on the toy dataset at `root` for `steps` AdamW steps at
    fixed seeds; returns per step {"loss", "image_loss", "action_loss", "gripper_loss"}."""
    torch.manual_seed(0)
    policy, _ = make_policy(root, **FIXTURE_POLICY_KWARGS)
    data = dataset_items(root, policy.config)
    n = next(iter(data.values())).shape[0]
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-3, weight_decay=0.0)
    order = torch.Generator().manual_seed(0)
    torch.manual_seed(1)  # diffusion steps and noise drawn inside the loss
    policy.train()
    losses = []
    for _ in range(steps):
        idx = torch.randint(0, n, (4,), generator=order)
        loss, info = policy.forward({k: v[idx] for k, v in data.items()})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append({"loss": loss.item(), **info})
    return losses


#: A 6-revolute-joint test arm (name, axis, origin xyz in the parent link frame), ending in a fixed "tool" link.
SIX_JOINT_LINKS = ["base_link", "link1", "link2", "link3", "link4", "link5", "link6", "tool"]
SIX_JOINTS = [
    ("j1", "0 0 1", "0 0 0.1"),
    ("j2", "0 1 0", "0 0 0.2"),
    ("j3", "0 1 0", "0.3 0 0"),
    ("j4", "1 0 0", "0.25 0 0"),
    ("j5", "0 1 0", "0.05 0 0"),
    ("j6", "1 0 0", "0.05 0 0"),
]


def six_joint_urdf() -> str:
    """The URDF text of the `SIX_JOINTS` arm."""
    links = SIX_JOINT_LINKS
    parts = ['<?xml version="1.0"?>', '<robot name="arm6">']
    parts += [f'  <link name="{n}"/>' for n in links]
    for i, (name, axis, xyz) in enumerate(SIX_JOINTS):
        parts.append(
            f'  <joint name="{name}" type="revolute">'
            f'<parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
            f'<limit lower="-3.0" upper="3.0" effort="10" velocity="1"/></joint>'
        )
    parts.append(
        '  <joint name="tool_fixed" type="fixed"><parent link="link6"/><child link="tool"/>'
        '<origin xyz="0.1 0 0" rpy="0 0 0"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)
