"""Overlay check: our rendered gripper on MetaWorld's own camera images.

Runs the scripted expert in ``gym_rnd_metaworld/<task>`` for a few steps, then for each camera draws

  1. the simulator image,
  2. our gripper render (symmetry texture) pasted at the TRUE EE pose read from ``observation.state``
     through the embodiment (what the policy sees),
  3. the outline of our render (green) over the simulator image, and MuJoCo's own gripper
     silhouette (segmentation render of the gripper geoms alone, magenta) with their IoU,
  4. the gripper rendered at the expert's next poses (every ``--stride`` steps, like an R&D action chunk)
     over the current image.

    MUJOCO_GL=egl python examples/overlay_check.py [--task reach-v3] [--steps 30] [--out outputs/overlay_metaworld.png]
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
from lerobot_rnd.sim.experts import MetaWorldExpert
from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv


def mujoco_gripper_mask(env: RnDMetaWorldEnv, camera: str, root_body: str = "right_hand", alone: bool = True):
    """Pixels where MuJoCo draws a geom of ``root_body``'s subtree (segmentation render); with ``alone``
    only those geoms are drawn (the arm and the sites would hide parts of the gripper)."""
    m = env.model
    root = m.body(root_body).id
    bodies = set()
    for b in range(m.nbody):
        a = b
        while a > 0 and a != root:
            a = int(m.body_parentid[a])
        if a == root:
            bodies.add(b)
    geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in bodies]
    r = mujoco.Renderer(m, *env.image_size)
    r.enable_segmentation_rendering()
    opt = mujoco.MjvOption()
    saved = m.geom_group.copy()
    if alone:
        m.geom_group[:] = 0
        m.geom_group[geoms] = 5
        opt.geomgroup[:] = 0
        opt.geomgroup[5] = 1
        opt.sitegroup[:] = 0
    try:
        r.update_scene(env.data, camera=camera, scene_option=opt)
    finally:
        m.geom_group[:] = saved
    seg = r.render()
    r.close()
    if camera in env.flip_cameras:
        seg = seg[::-1, ::-1]
    return np.isin(seg[..., 0], geoms) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))


def render_gripper(
    emb, key: str, T_world_ee: torch.Tensor, T_world_ee_now: torch.Tensor, textured: bool = True
):
    """Render the camera's mesh at EE poses (N,4,4); the camera pose is taken at the current EE pose."""
    cam = emb.cameras[key]
    meshes = emb.mesh_batch(textured=textured)
    T_world_cam = cam.T_world_cam_at(T_world_ee_now)  # (4,4)
    T_cam_ee = invert_transform(T_world_cam)[None] @ T_world_ee
    n = T_world_ee.shape[0]
    out = render(
        meshes,
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
    p.add_argument("--task", default="reach-v3")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=30, help="expert steps before the snapshot")
    p.add_argument("--horizon", type=int, default=4, help="future poses drawn in panel 4")
    p.add_argument("--stride", type=int, default=6, help="steps between drawn future poses")
    p.add_argument("--scale", type=int, default=3, help="upscaling of the 128x128 images")
    p.add_argument("--flip-corner2", action="store_true", help="turn corner2 by 180 degrees (LeRobot style)")
    p.add_argument("--out", default="outputs/overlay_metaworld.png")
    a = p.parse_args()

    env = RnDMetaWorldEnv(a.task, flip_cameras=("corner2",) if a.flip_corner2 else ())
    expert = MetaWorldExpert(a.task)
    obs, _ = env.reset(seed=a.seed)
    for _ in range(a.steps):
        obs, *_ = env.step(expert(env.raw_observation))
    emb = env.embodiment()
    state_now = torch.as_tensor(obs["agent_pos"], dtype=torch.float64)
    images = {c: obs["pixels"][c].copy() for c in env.camera_names}
    gt_masks = {c: mujoco_gripper_mask(env, c) for c in env.camera_names}
    future_states = []
    for _ in range(a.horizon):
        for _ in range(a.stride):
            o, *_ = env.step(expert(env.raw_observation))
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
        for i, title in enumerate(["simulator", "render @ true EE pose", f"ours green / MuJoCo magenta IoU {iou:.2f}",
                                   f"next {a.horizon} poses (every {a.stride} steps)"]):  # fmt: skip
            d.text((i * W + 4, 4), f"{cam_name}: {title}" if i == 0 else title, fill=(255, 255, 0))
        rows.append(np.asarray(pil))
        print(f"{cam_name}: IoU(our mask, MuJoCo gripper) = {iou:.3f}  ({mask.sum()} vs {gt.sum()} px)")
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(rows, axis=0)).save(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
