"""Can the SO-101's front camera tell where reach-target's ball is? Balls along one viewing ray, with and without
the post under them.

A single camera sees a point only up to its depth along the viewing ray. This script takes the front camera's ray
through the centre of reach-target's placement range, keeps the stretch of it inside the range (x, y, height),
puts the ball at ``--points`` evenly spaced positions on that stretch and, per position: the ball's projected
centre and diameter in pixels (pinhole model from the env's exact camera, independent of the renderer) and the
front image rendered with the post hidden (the ball floating, as the suite had it first) and shown (as now). For
each pair of positions it reports how far apart (in 3-D) they are and how many pixels of the front image differ,
with and without the post. Writes a JSON table and a picture (one row per position: floating | on its post).

    python benchmarks/so101_reach_ray.py --out docs/images/so101_reach_ray.png \
        --json benchmarks/results/so101_reach_ray.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def ray_through_range_centre(cam, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, end): the stretch of the camera's ray through the range's centre that lies inside the box
    [low, high] (world frame, metres)."""
    T_world_cam = np.asarray(cam.T_world_cam, dtype=np.float64)
    origin = T_world_cam[:3, 3]
    direction = (low + high) / 2 - origin
    direction /= np.linalg.norm(direction)
    with np.errstate(divide="ignore"):
        t1, t2 = (low - origin) / direction, (high - origin) / direction
    t_in, t_out = np.minimum(t1, t2).max(), np.maximum(t1, t2).min()
    return origin + t_in * direction, origin + t_out * direction


def ball_in_image(cam, point_world: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """Pixel (u, v) of a ball's centre (world point) and its diameter in pixels (the camera's pinhole model)."""
    uv, depth = cam.project(point_world[None])
    return uv[0].numpy(), float(2 * radius * cam.K[0, 0] / depth[0])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=3, help="ball positions along the ray (default 3)")
    ap.add_argument("--size", type=int, default=128, help="image side in pixels (default 128, the recorder's)")
    ap.add_argument("--out", type=Path, help="picture (PNG)")
    ap.add_argument("--json", type=Path, help="table (JSON)")
    a = ap.parse_args(argv)
    if a.points < 2:
        ap.error(f"--points must be at least 2, got {a.points}")
    import cv2

    from lerobot_rnd.sim.so101_env import PLACEMENT_RANGES, RnDSO101Env
    from lerobot_rnd.sim.so101_scene import TARGET_RADIUS

    env = RnDSO101Env("reach-target", observation_height=a.size, observation_width=a.size)
    cam = env.embodiment().cameras["observation.images.front"]
    low, high = PLACEMENT_RANGES["reach-target"]
    start, end = ray_through_range_centre(cam, low, high)
    post = env.model.geom("target_post").id
    rows, images = [], []
    for f in np.linspace(0.0, 1.0, a.points):
        ball = start + f * (end - start)
        pair = []
        for shown in (False, True):
            env.model.geom_rgba[post, 3] = 1.0 if shown else 0.0
            obs, _ = env.reset(options={"placement": ball.tolist()})
            pair.append(obs["pixels"]["front"])
        uv, diameter = ball_in_image(cam, ball, TARGET_RADIUS)
        rows.append({"ball_world": np.round(ball, 4).tolist(), "pixel_uv": np.round(uv, 1).tolist(),
                     "diameter_px": round(diameter, 1)})  # fmt: skip
        images.append(pair)
    pairs = []
    for i in range(a.points):
        for j in range(i + 1, a.points):
            changed = [int((np.abs(images[i][k].astype(int) - images[j][k]).max(-1) > 30).sum()) for k in (0, 1)]
            pairs.append({"positions": [i, j], "apart_m": round(float(np.linalg.norm(
                np.subtract(rows[i]["ball_world"], rows[j]["ball_world"]))), 3),
                "pixels_changed_floating": changed[0], "pixels_changed_on_post": changed[1]})  # fmt: skip
    print(f"front camera ray through the range's centre, {a.size}-px images; ball radius {TARGET_RADIUS * 1000:.0f} mm")
    print(f"{'position':>8} {'ball x, y, z [m]':>24} {'pixel u, v':>14} {'diameter px':>12}")
    for i, r in enumerate(rows):
        print(f"{i:>8} {r['ball_world']!s:>24} {r['pixel_uv']!s:>14} {r['diameter_px']:>12}")
    print(f"{'pair':>8} {'apart [m]':>10} {'pixels changed, floating':>25} {'on its post':>12}")
    for p in pairs:
        print(f"{p['positions']!s:>8} {p['apart_m']:>10} {p['pixels_changed_floating']:>25} "
              f"{p['pixels_changed_on_post']:>12}")  # fmt: skip
    if a.out:
        big = [[cv2.resize(im, (2 * a.size, 2 * a.size), interpolation=cv2.INTER_NEAREST) for im in pair]
               for pair in images]  # fmt: skip
        for i, (r, pair) in enumerate(zip(rows, big)):
            for im, label in zip(pair, ("floating", "on its post")):
                cv2.putText(im, f"{label}: z {r['ball_world'][2] * 100:.0f} cm", (4, 2 * a.size - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                            (20, 20, 20), 1, cv2.LINE_AA)  # fmt: skip
        grid = np.concatenate([np.concatenate(pair, 1) for pair in big], 0)
        a.out.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(a.out), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR))
        print(f"wrote {a.out}")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({
            "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *(argv if argv is not None else sys.argv[1:])]),
            "image_size": a.size, "ray_start_world": np.round(start, 4).tolist(),
            "ray_end_world": np.round(end, 4).tolist(), "positions": rows, "pairs": pairs,
            "pixels_changed": "pixels whose RGB differs by more than 30 in some channel between the two front images",
        }, indent=1) + "\n")  # fmt: skip
        print(f"wrote {a.json}")
    env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
