#!/usr/bin/env python
"""Where the reach-v3 goal appears in each MetaWorld camera: in view, unoccluded, how many pixels wide.

reach-v3's observation has no goal position (`observation.state` is the hand), so a policy must find the goal
in the images. This script resets reach-v3 at random placements, projects the goal (MetaWorld's `_target_pos`)
into every camera with MuJoCo's own camera pose and field of view, checks the rendered depth at that pixel (the
goal marker is hidden when something nearer covers it) and writes a JSON and a picture of the first placements
with the projected goal circled.

    MUJOCO_GL=egl python benchmarks/reach_goal_views.py      # ~1 min on 2 cores

Placement seeds 500-... (neither the demos' seed 0 nor the evaluation seeds 1000-...).
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CAMERAS = ("corner2", "behindGripper", "topview", "corner3", "corner")


def project(model, data, cam: str, point: np.ndarray, size: int) -> tuple[float, float, float]:
    """(u, v, depth) of a world point in a MuJoCo camera (pixels from the top-left corner, metres along the axis)."""
    import mujoco

    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cam)
    p_cam = data.cam_xmat[cid].reshape(3, 3).T @ (point - data.cam_xpos[cid])  # MuJoCo cameras look along -z
    f = size / 2 / np.tan(np.radians(model.cam_fovy[cid] / 2))
    depth = -p_cam[2]
    return (size - 1) / 2 + f * p_cam[0] / depth, (size - 1) / 2 - f * p_cam[1] / depth, depth


def ray_length_in_box(origin: np.ndarray, point: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """Length (m) of the line through origin and point inside the axis-aligned box [low, high] (slab method)."""
    d = (point - origin) / np.linalg.norm(point - origin)
    parallel = np.abs(d) < 1e-12
    if np.any(parallel & ((origin < low) | (origin > high))):
        return 0.0  # parallel to a slab it lies outside
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (low - origin) / d, (high - origin) / d
    t_near = np.nanmax(np.where(parallel, -np.inf, np.minimum(t1, t2)))
    t_far = np.nanmin(np.where(parallel, np.inf, np.maximum(t1, t2)))
    return float(max(0.0, t_far - t_near))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--placements", type=int, default=40)
    p.add_argument("--seed", type=int, default=500)
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--out", default="benchmarks/results/archive/reach_goal_views.json")
    p.add_argument("--image", default="docs/images/reach_goal_views.png")
    a = p.parse_args(argv)

    import cv2
    import mujoco

    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv

    env = RnDMetaWorldEnv("reach-v3", camera_names=CAMERAS)
    model, data = env.model, env.data
    depth_renderer = mujoco.Renderer(model, height=a.size, width=a.size)
    depth_renderer.enable_depth_rendering()
    radius = float(model.site("goal").size[0]) if "goal" in [model.site(i).name for i in range(model.nsite)] else None
    per_cam = {c: {"in_view": 0, "visible": 0, "diameter_px": [], "ray_m": []} for c in CAMERAS}
    goal_low, goal_high = env.placement_space.low[3:6], env.placement_space.high[3:6]  # rand_vec = (hand, goal)
    tiles = []
    for k in range(a.placements):
        obs, _ = env.reset(seed=a.seed + k)
        goal = np.asarray(env._env._target_pos, dtype=np.float64)
        row = []
        for cam in CAMERAS:
            u, v, depth = project(model, data, cam, goal, a.size)
            stats = per_cam[cam]
            cam_pos = data.cam_xpos[model.camera(cam).id]
            stats["ray_m"].append(ray_length_in_box(cam_pos, goal, goal_low, goal_high))
            inside = depth > 0 and 0 <= u < a.size and 0 <= v < a.size
            visible = False
            if inside:
                stats["in_view"] += 1
                depth_renderer.update_scene(data, camera=cam)
                rendered = depth_renderer.render()[int(v), int(u)]
                visible = bool(rendered > depth - 2 * (radius or 0.02))  # nothing nearer than the marker's front
                stats["visible"] += visible
                if radius:
                    f = a.size / 2 / np.tan(np.radians(model.cam_fovy[model.camera(cam).id] / 2))
                    stats["diameter_px"].append(2 * radius * f / depth)
            if k < 3:
                img = cv2.resize(obs["pixels"][cam], (2 * a.size, 2 * a.size), interpolation=cv2.INTER_NEAREST)
                colour = (0, 255, 0) if visible else (255, 255, 0)
                cv2.circle(img, (int(2 * u), int(2 * v)), 12, colour, 1)
                cv2.putText(img, cam, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1)
                row.append(img)
        if row:
            tiles.append(np.concatenate(row, axis=1))
    depth_renderer.close()
    env.close()
    summary = {
        cam: {"in_view": s["in_view"], "visible": s["visible"], "placements": a.placements,
              "marker_diameter_px": [round(min(s["diameter_px"]), 2), round(max(s["diameter_px"]), 2)]
              if s["diameter_px"] else None,
              "ray_length_in_goal_box_m": [round(float(np.min(s["ray_m"])), 3), round(float(np.median(s["ray_m"])), 3),
                                           round(float(np.max(s["ray_m"])), 3)]}  # fmt: skip
        for cam, s in per_cam.items()
    }
    res = {"command": "python benchmarks/reach_goal_views.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "image_size": a.size, "placement_seeds": [a.seed, a.seed + a.placements - 1],
           "goal_marker_radius_m": radius, "goal_box": [goal_low.tolist(), goal_high.tolist()], "cameras": summary}  # fmt: skip
    Path(a.out).write_text(json.dumps(res, indent=1))
    cv2.imwrite(a.image, cv2.cvtColor(np.concatenate(tiles, axis=0), cv2.COLOR_RGB2BGR))
    print(f"| camera | goal in view | goal unoccluded | marker diameter (px at {a.size}) | ray length in the goal box, "
          "min / median / max (cm) |")
    print("| --- | ---: | ---: | --- | --- |")
    for cam, s in summary.items():
        d = s["marker_diameter_px"]
        print(f"| {cam} | {s['in_view']}/{a.placements} | {s['visible']}/{a.placements} | "
              f"{'–' if d is None else f'{d[0]:.1f}-{d[1]:.1f}'} | "
              f"{' / '.join(f'{100 * x:.0f}' for x in s['ray_length_in_goal_box_m'])} |")  # fmt: skip
    print(f"wrote {a.out} and {a.image}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
