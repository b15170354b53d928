"""How large the task object appears in a simulated suite's cameras (Panda, SO-101), over the placement range.

For the centre and the four (x, y) corners of a task's placement range (the other placement coordinates at the
range's centre: yaw 0, the SO-101 ball's middle height; push-block and pick-place draw their target with a seeded
generator until valid, as the benchmark's grid: ``complete_placement``), resets the suite's env there and, per camera at
the start pose, projects the object's eight box corners (a ball: the eight corners of its camera-aligned bounding
cube, taken in the plane through its centre) with the camera's pinhole model (MuJoCo's ``fovy``, position and
orientation, independent of the renderer) and reports the object's projected width in pixels, how many of those
points lie inside the image, and how many pixels of it are seen (MuJoCo's segmentation rendering: what the gripper
hides is not counted). Writes a JSON table and a picture (one row per placement: front | wrist, the projected box
outlined).

    python benchmarks/camera_views.py --task lift-cube --out docs/images/panda_lift_views.png \
        --json benchmarks/results/panda_camera_views_lift-cube.json
    python benchmarks/camera_views.py --suite so101 --task reach-target --out docs/images/so101_reach_views.png \
        --json benchmarks/results/so101_camera_views_reach-target.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from lerobot_rnd.sim.placements import complete_placement

os.environ.setdefault("MUJOCO_GL", "egl")


#: the body of each task's object: its first box geom (a ball for SO-101 reach-target) is what is measured
OBJECT_BODY = {
    "lift-cube": "cube", "pick-place": "cube", "push-block": "block", "slide-block": "block", "press-button": "button_box",  # Panda
    "lift-red-cube": "red_cube", "lift-blue-cube": "blue_cube",  # Panda, two cubes: the one to lift
    "pick-cube": "cube", "reach-target": "target",  # SO-101
}  # fmt: skip
_BOX, _SPHERE = 6, 2  # mjGEOM_BOX, mjGEOM_SPHERE
_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


def object_geom(env) -> int:
    """Geom id of the task object's first box (the cube, block or button housing), or its ball."""
    m = env.model
    bid = m.body(OBJECT_BODY[env.task]).id
    return next(g for g in range(m.ngeom) if m.geom_bodyid[g] == bid and m.geom_type[g] in (_BOX, _SPHERE))


def object_points_world(env, T_world_cam: np.ndarray) -> np.ndarray:
    """(8, 3) world points whose projection spans the object: a box's corners; for a ball, the corners of the
    camera-aligned square through its centre (+-r along the camera's x and y), doubled to keep 8 rows."""
    m, d = env.model, env.data
    gid = object_geom(env)
    centre = np.asarray(d.geom_xpos[gid], dtype=np.float64)
    if m.geom_type[gid] == _SPHERE:
        r = float(m.geom_size[gid][0])
        return centre + (_SIGNS[:, :2] * r) @ T_world_cam[:3, :2].T
    half = np.asarray(m.geom_size[gid], dtype=np.float64)
    R = np.asarray(d.geom_xmat[gid], dtype=np.float64).reshape(3, 3)
    return centre + (_SIGNS * half) @ R.T


def project(K: np.ndarray, T_world_cam: np.ndarray, p_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (u, v) of world points (N, 3) and their depth along the optical axis (N,)."""
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    p_cam = (p_world - t) @ R
    uv = (p_cam @ K.T)[:, :2] / p_cam[:, 2:3]
    return uv, p_cam[:, 2]


def camera_now(env, mujoco_camera: str, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(K, T_world_cam) of a MuJoCo camera where it is now: ``fy = H / 2 / tan(fovy / 2)``, square pixels,
    principal point at the image centre; MuJoCo cameras look along -z with y up."""
    m, d = env.model, env.data
    cid = m.camera(mujoco_camera).id
    f = 0.5 * size[0] / np.tan(np.radians(float(m.cam_fovy[cid])) / 2)
    K = np.array([[f, 0.0, (size[1] - 1) / 2], [0.0, f, (size[0] - 1) / 2], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = np.asarray(d.cam_xmat[cid], dtype=np.float64).reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = d.cam_xpos[cid]
    return K, T


def corner_placements(env) -> dict[str, np.ndarray]:
    low, high = (np.asarray(v, dtype=np.float64) for v in (env.placement_space.low, env.placement_space.high))
    centre = (low + high) / 2
    out = {}
    corners = {"near-left": (1, 0), "near-right": (1, 1), "far-left": (0, 0), "far-right": (0, 1)}
    for name, corner in {"centre": None, **corners}.items():
        p = centre.copy()
        if corner is not None:
            p[0], p[1] = low[0] if corner[0] == 0 else high[0], low[1] if corner[1] == 0 else high[1]
        valid = complete_placement(env, p, dims=(0, 1, 2), rng=np.random.default_rng(0))  # a target that fits
        out[name] = p if valid is None else valid
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suite", choices=("panda", "so101"), default="panda")
    ap.add_argument("--task", default="lift-cube")
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--out", type=Path, required=True, help="PNG picture")
    ap.add_argument("--json", type=Path, default=None, help="JSON table (default: next to --out)")
    args = ap.parse_args(argv)

    import cv2
    import mujoco

    size = (args.image_size, args.image_size)
    if args.suite == "panda":
        from lerobot_rnd.sim.panda_env import RnDPandaEnv as Env
    else:
        from lerobot_rnd.sim.so101_env import RnDSO101Env as Env
    env = Env(args.task, observation_height=size[0], observation_width=size[1])
    segmenter = mujoco.Renderer(env.model, *size)
    segmenter.enable_segmentation_rendering()
    gid = object_geom(env)
    rows, tiles = [], []
    for name, placement in corner_placements(env).items():
        obs, _ = env.reset(seed=0, options={"placement": placement})
        row = {"placement": name, "object_xyz_yaw": [round(float(v), 4) for v in placement[:3]], "cameras": {}}
        imgs = []
        for cam in env.camera_names:
            K, T_world_cam = camera_now(env, env.mujoco_camera_name(cam), size)
            box = object_points_world(env, T_world_cam)
            uv, depth = project(K, T_world_cam, box)
            inside = (depth > 0) & np.all((uv >= -0.5) & (uv <= np.array(size[::-1]) - 0.5), axis=1)
            width = float(uv[:, 0].max() - uv[:, 0].min()) if np.all(depth > 0) and inside.any() else 0.0
            segmenter.update_scene(env.data, camera=env.mujoco_camera_name(cam))
            seg = segmenter.render()
            mask = (seg[..., 0] == gid) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))
            seen = int(mask.sum())
            cols = np.flatnonzero(mask.any(axis=0))
            row["cameras"][cam] = {
                "width_px": round(width, 1),
                "visible_px": seen,
                "visible_width_px": int(cols[-1] - cols[0] + 1) if seen else 0,
                "corners_in_view": int(inside.sum()),
                "distance_m": round(float(np.linalg.norm(box.mean(0) - T_world_cam[:3, 3])), 3),
            }
            img = np.ascontiguousarray(obs["pixels"][cam])
            img = cv2.resize(img, (256, 256), interpolation=cv2.INTER_NEAREST)
            if width > 0:
                s = 256 / args.image_size
                x0, y0 = np.floor((uv.min(0) + 0.5) * s).astype(int)
                x1, y1 = np.ceil((uv.max(0) + 0.5) * s).astype(int)
                cv2.rectangle(img, (int(x0), int(y0)), (int(x1), int(y1)), (255, 255, 0), 1)
            cv2.putText(img, f"{name} {cam}: {width:.0f} px wide, {seen} px seen", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                        (255, 255, 255), 1, cv2.LINE_AA)
            imgs.append(img)
        tiles.append(np.concatenate(imgs, axis=1))
        rows.append(row)
    segmenter.close()
    env.close()

    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), cv2.cvtColor(np.concatenate(tiles, axis=0), cv2.COLOR_RGB2BGR))
    out_json = args.json or args.out.with_suffix(".json")
    out_json.parent.mkdir(parents=True, exist_ok=True)
    record = {
        "command": "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
        "suite": args.suite,
        "task": args.task,
        "image_size": args.image_size,
        "rows": rows,
    }
    out_json.write_text(json.dumps(record, indent=1) + "\n")
    cams = list(rows[0]["cameras"])
    print(f"{'placement':12s} " + " ".join(f"{c + ' wide':>11s} {c + ' seen':>11s} {c + ' in':>9s}" for c in cams))
    for r in rows:
        print(f"{r['placement']:12s} " + " ".join(
            f"{r['cameras'][c]['width_px']:8.1f} px {r['cameras'][c]['visible_px']:8d} px "
            f"{r['cameras'][c]['corners_in_view']:7d}/8" for c in cams))
    print(f"wrote {args.out} and {out_json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
