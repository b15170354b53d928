"""Overlay check: our rendered gripper on the simulator's own camera images (MetaWorld or Panda suite).

Runs the scripted expert in ``gym_rnd_metaworld/<task>`` or ``gym_rnd_panda/<task>`` for a few steps, then for
each camera draws

  1. the simulator image,
  2. our gripper render (symmetry texture) pasted at the TRUE EE pose read from ``observation.state``
     through the embodiment (what the policy sees),
  3. the outline of our render (green) over the simulator image, and MuJoCo's own gripper silhouette
     (segmentation render of the same gripper geoms alone, magenta) with their IoU,
  4. the gripper rendered at the EE poses the expert reaches next (every ``--stride`` steps, like an R&D
     action chunk) over the current image.

    MUJOCO_GL=egl python examples/overlay_check.py [--task reach-v3] [--steps 30] [--out outputs/overlay_metaworld.png]
    MUJOCO_GL=egl python examples/overlay_check.py --suite panda [--task lift-cube] [--steps 9] \\
        [--out outputs/overlay_panda.png]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
import torch
from PIL import Image, ImageDraw

from lerobot_rnd.geometry import invert_transform
from lerobot_rnd.rendering import render

#: per suite: default arguments and the MuJoCo bodies whose subtrees make the "full" / "fingers" meshes
SUITES = {
    "metaworld": dict(
        task="reach-v3", seed=0, steps=30, stride=6, out="outputs/overlay_metaworld.png",
        roots={"full": ("right_hand",), "fingers": ("rightclaw", "leftclaw")},
    ),
    "panda": dict(
        task="lift-cube", seed=3, steps=9, stride=2, out="outputs/overlay_panda.png",
        roots={"full": ("base_mount",), "fingers": ("right_follower", "left_follower")},
    ),
}  # fmt: skip


def make_env_and_expert(suite: str, task: str, size: int, flip_corner2: bool, cameras: list[str] | None = None):
    if suite == "metaworld":
        from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv
        from lerobot_rnd.sim.metaworld_experts import MetaWorldExpert

        env = RnDMetaWorldEnv(
            task, observation_height=size, observation_width=size,
            flip_cameras=("corner2",) if flip_corner2 else (), **({"camera_names": cameras} if cameras else {}),
        )  # fmt: skip
        return env, MetaWorldExpert(task)
    from lerobot_rnd.sim.panda_env import RnDPandaEnv
    from lerobot_rnd.sim.panda_experts import PandaExpert

    env = RnDPandaEnv(task, observation_height=size, observation_width=size, terminate_on_success=False)
    return env, PandaExpert(task)


def subtree_geoms(model, roots) -> list[int]:
    """Visible geoms (groups 0-2, not transparent) of the ``roots`` bodies and their subtrees."""
    ids = {model.body(r).id for r in roots}
    out = []
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        while b > 0 and b not in ids:
            b = int(model.body_parentid[b])
        if b in ids and int(model.geom_group[g]) <= 2 and model.geom_rgba[g][3] > 0:
            out.append(g)
    return out


def mujoco_gripper_mask(env, camera: str, roots) -> np.ndarray:
    """Pixels where MuJoCo draws the visual geoms of the ``roots`` subtrees, drawn alone (no occlusion)."""
    m = env.model
    geoms = subtree_geoms(m, roots)
    r = mujoco.Renderer(m, *env.image_size)
    r.enable_segmentation_rendering()
    opt = mujoco.MjvOption()
    saved = m.geom_group.copy()
    m.geom_group[:] = 0
    m.geom_group[geoms] = 5
    opt.geomgroup[:] = 0
    opt.geomgroup[5] = 1
    opt.sitegroup[:] = 0
    try:
        r.update_scene(env.data, camera=env.mujoco_camera_name(camera), scene_option=opt)
        seg = r.render()
    finally:
        m.geom_group[:] = saved
        r.close()
    if camera in env.flip_cameras:
        seg = seg[::-1, ::-1]
    return np.isin(seg[..., 0], geoms) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))


def render_gripper(emb, key: str, T_world_ee: torch.Tensor, T_world_ee_now: torch.Tensor, textured=True):
    """Render the camera's mesh at EE poses (N,4,4); the camera pose is taken at the current EE pose."""
    cam = emb.cameras[key]
    T_world_cam = cam.T_world_cam_at(T_world_ee_now)
    T_cam_ee = invert_transform(T_world_cam)[None] @ T_world_ee
    n = T_world_ee.shape[0]
    out = render(
        emb.mesh_batch(textured=textured),
        torch.full((n,), emb.mesh_index(key), dtype=torch.long),
        T_cam_ee.float(),
        cam.K_tensor()[None].expand(n, 3, 3),
        cam.image_size,
    )
    return out.rgb.permute(0, 2, 3, 1).numpy(), out.mask.numpy()


def outline(mask: np.ndarray) -> np.ndarray:
    m = mask.astype(bool)
    inner = m.copy()
    inner[1:-1, 1:-1] = m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
    return m & ~inner


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--suite", choices=sorted(SUITES), default="metaworld")
    p.add_argument("--task", default=None, help="default: reach-v3 (metaworld) / lift-cube (panda)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--steps", type=int, default=None, help="expert steps before the snapshot")
    p.add_argument("--horizon", type=int, default=4, help="future poses drawn in panel 4")
    p.add_argument("--stride", type=int, default=None, help="steps between drawn future poses")
    p.add_argument("--size", type=int, default=128, help="image size")
    p.add_argument("--scale", type=int, default=3, help="upscaling of the images in the PNG")
    p.add_argument("--flip-corner2", action="store_true", help="metaworld: turn corner2 by 180 degrees (LeRobot)")
    p.add_argument("--cameras", default=None, help="metaworld: comma-separated cameras (default: the env's)")
    p.add_argument("--out", default=None)
    a = p.parse_args()
    suite = SUITES[a.suite]
    for name in ("task", "seed", "steps", "stride", "out"):
        if getattr(a, name) is None:
            setattr(a, name, suite[name])

    if a.cameras and a.suite != "metaworld":
        p.error("--cameras: only the metaworld suite takes a camera list (the panda env has fixed cameras)")
    cameras = [c.strip() for c in a.cameras.split(",")] if a.cameras else None
    env, expert = make_env_and_expert(a.suite, a.task, a.size, a.flip_corner2, cameras)
    obs, _ = env.reset(seed=a.seed)
    for _ in range(a.steps):
        obs, *_ = env.step(expert.act(env))
    emb = env.embodiment()
    state_now = torch.as_tensor(obs["agent_pos"], dtype=torch.float64)
    images = {c: obs["pixels"][c].copy() for c in env.camera_names}
    gt_masks = {
        c: mujoco_gripper_mask(env, c, suite["roots"][emb.camera_mesh[f"observation.images.{c}"]])
        for c in env.camera_names
    }
    future_states = []
    for _ in range(a.horizon):
        for _ in range(a.stride):
            o, *_ = env.step(expert.act(env))
        future_states.append(torch.as_tensor(o["agent_pos"], dtype=torch.float64))
    src = emb.ee_pose_source
    T_now = src.ee_pose(state_now)
    T_future = src.ee_pose(torch.stack(future_states))

    S = a.scale
    rows = []
    for cam_name in env.camera_names:
        key = f"observation.images.{cam_name}"
        img = images[cam_name].astype(np.float32) / 255.0
        rgb, mask = render_gripper(emb, key, T_now[None], T_now)
        rgb, mask = rgb[0], mask[0]
        pasted = np.where(mask[..., None], rgb, img)
        gt = gt_masks[cam_name]
        iou = (gt & mask).sum() / max(1, (gt | mask).sum())
        lines = img.copy()
        lines[outline(gt)] = (1.0, 0.0, 1.0)
        lines[outline(mask)] = (0.0, 1.0, 0.0)
        frgb, fmask = render_gripper(emb, key, T_future, T_now)
        fut = img.copy()
        for k in range(len(T_future) - 1, -1, -1):  # nearest step drawn last
            alpha = 0.35 + 0.65 * (1 - k / max(1, len(T_future) - 1))
            fut = np.where(fmask[k][..., None], alpha * frgb[k] + (1 - alpha) * fut, fut)
        panels = [img, pasted, lines, fut]
        row = np.concatenate([np.kron(pn, np.ones((S, S, 1))) for pn in panels], axis=1)
        pil = Image.fromarray((np.clip(row, 0, 1) * 255).astype(np.uint8))
        d = ImageDraw.Draw(pil)
        W = img.shape[1] * S
        for i, title in enumerate(["simulator", f"render @ true EE pose ({emb.camera_mesh[key]})",
                                   f"ours green / MuJoCo magenta IoU {iou:.2f}",
                                   f"next {a.horizon} poses (every {a.stride} steps)"]):  # fmt: skip
            d.text((i * W + 4, 4), f"{cam_name}: {title}" if i == 0 else title, fill=(255, 255, 0))
        rows.append(np.asarray(pil))
        print(f"{cam_name}: IoU(our mask, MuJoCo gripper) = {iou:.3f}  ({mask.sum()} vs {gt.sum()} px)")
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(rows, axis=0)).save(out)
    print(f"wrote {out}")
    env.close()


if __name__ == "__main__":
    main()
