"""Renders per second of lerobot_rnd.rendering for the R&D shapes.

One training step renders B samples x P poses (history + horizon, default 11) x C cameras
(default 2) at S x S (default 128). Camera 0 sees the gripper from ~0.5 m (a scene
camera), camera 1 from ~0.15 m (a wrist camera: larger triangles). Paths measured:

* ``render``  : the plain function (builds a Rasterizer and allocates outputs every call)
* ``dynamic`` : a Rasterizer built once, exact tiers, outputs written into reused buffers
* ``static``  : the fixed-shape path (capacities calibrated on the same poses, margin 1.5)
* ``static+graph`` (CUDA only): the static path replayed from a captured CUDA graph

Besides wall time, the process CPU time per call (all threads) is printed: on a shared
machine it measures the work more robustly than the wall clock.

Examples:
    python benchmarks/bench_render.py                       # CPU (and CUDA if present)
    python benchmarks/bench_render.py --faces 1000 --batch 8 --device cpu --out bench.json
    python benchmarks/bench_render.py --mesh path/to/gripper.stl --cull
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import time

import torch
import trimesh

from lerobot_rnd.geometry import make_transform, so3_exp
from lerobot_rnd.rendering import MeshBatch, Rasterizer, RenderOutput, render


def build_mesh(shape: str, faces: int, path: str | None) -> trimesh.Trimesh:
    if path:
        mesh = trimesh.load(path, force="mesh")
        if len(mesh.faces) > faces:
            try:
                mesh = mesh.simplify_quadric_decimation(face_count=faces)
            except Exception as e:  # optional dependency (fast_simplification) missing
                print(f"[bench] could not simplify {path} to {faces} faces ({e}); using {len(mesh.faces)}")
        # scale to a ~15 cm gripper
        mesh.apply_scale(0.15 / max(mesh.extents))
        mesh.apply_translation(-mesh.bounds.mean(0))
        return mesh
    if shape == "capsule":
        a = max(3, int(round(math.sqrt(faces / 2))))
        b = max(3, int(round(faces / (2 * a))))
        return trimesh.creation.capsule(height=0.10, radius=0.025, count=[a, b])
    if shape == "icosphere":
        k = max(0, int(math.floor(math.log(max(faces, 20) / 20, 4))))
        return trimesh.creation.icosphere(subdivisions=k, radius=0.06)
    if shape == "gripper":
        parts = [
            trimesh.creation.box(extents=[0.12, 0.04, 0.03]),
            trimesh.creation.box(extents=[0.015, 0.02, 0.06], transform=trimesh.transformations.translation_matrix([0.04, 0, 0.045])),
            trimesh.creation.box(extents=[0.015, 0.02, 0.06], transform=trimesh.transformations.translation_matrix([-0.04, 0, 0.045])),
        ]
        mesh = trimesh.util.concatenate(parts)
        while len(mesh.faces) * 4 <= faces:
            mesh = mesh.subdivide()
        a = max(3, int(round(math.sqrt(max(faces - len(mesh.faces), 18) / 2))))
        wrist = trimesh.creation.capsule(height=0.04, radius=0.03, count=[a, a])
        wrist.apply_translation([0, 0, -0.05])
        return trimesh.util.concatenate([mesh, wrist])
    raise ValueError(shape)


def make_poses(B: int, P: int, C: int, S: int, seed: int = 0):
    """T_cam_obj (B*P*C, 4, 4) and K (B*P*C, 3, 3): per sample a base pose, P perturbed
    future poses (like an action chunk), seen by C cameras."""
    g = torch.Generator().manual_seed(seed)
    f = (S / 2) / math.tan(math.radians(45) / 2)  # fovy 45 degrees
    K = torch.tensor([[f, 0, (S - 1) / 2], [0, f, (S - 1) / 2], [0, 0, 1.0]])
    dist = [0.5, 0.15] + [0.35] * max(0, C - 2)
    Ts = []
    for b in range(B):
        base_r = torch.randn(3, generator=g)
        for p in range(P):
            r = base_r + 0.05 * p * torch.randn(3, generator=g)
            for c in range(C):
                t = torch.tensor([0.0, 0.0, dist[c]]) + 0.02 * torch.randn(3, generator=g) * (1 + p / P)
                Ts.append(make_transform(so3_exp(r), t))
    T = torch.stack(Ts)
    return T, K.expand(T.shape[0], 3, 3).contiguous()


def timeit(fn, iters: int, warmup: int, sync=lambda: None) -> tuple[list[float], list[float]]:
    """Wall-clock and process CPU seconds (all threads) per call."""
    for _ in range(warmup):
        fn()
    sync()
    wall, cpu = [], []
    for _ in range(iters):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        sync()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return wall, cpu


def bench_device(device: torch.device, mesh: trimesh.Trimesh, args) -> list[dict]:
    mb = MeshBatch.from_meshes([(mesh.vertices, mesh.faces, None)], device=device)
    T, K = make_poses(args.batch, args.poses, args.cameras, args.size)
    N = T.shape[0]
    T, K = T.to(device), K.to(device)
    mi = torch.zeros(N, dtype=torch.long, device=device)
    hw = (args.size, args.size)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    rows = []

    def record(path, timing, extra=None):
        times, cpu = timing
        med = statistics.median(times)
        best = min(times)
        cpu_best = min(cpu)
        row = dict(
            device=str(device), path=path, renders_per_call=N, faces=len(mesh.faces), image=args.size,
            cull_backfaces=args.cull, ms_median=med * 1e3, ms_best=best * 1e3,
            renders_per_s_median=N / med, renders_per_s_best=N / best, cpu_ms_best=cpu_best * 1e3,
        )
        row.update(extra or {})
        rows.append(row)
        print(f"{str(device):6s} {path:13s} N={N:4d} F={len(mesh.faces):5d} {args.size}px  "
              f"median {med * 1e3:8.2f} ms  best {best * 1e3:8.2f} ms  -> {N / med:7.0f} renders/s "
              f"(best {N / best:.0f})  process CPU {cpu_best * 1e3:7.1f} ms", flush=True)

    with torch.no_grad():
        record("render", timeit(lambda: render(mb, mi, T, K, hw, cull_backfaces=args.cull), args.iters, args.warmup, sync))
        rast = Rasterizer(mb, hw, device=device, cull_backfaces=args.cull)
        buf = RenderOutput(
            torch.empty(N, 3, *hw, device=device), torch.empty(N, *hw, dtype=torch.bool, device=device),
            torch.empty(N, 3, *hw, device=device),
        )
        record("dynamic", timeit(lambda: rast(mi, T, K, dynamic=True, out=buf), args.iters, args.warmup, sync))
        cov = buf.mask.float().mean().item()
        if not args.no_static:
            rast.calibrate(mi, T, K, margin=1.5)
            out = rast(mi, T, K, out=buf)
            extra = dict(overflow=bool(out.overflow.any().item()), candidates_per_render=rast.candidates_per_render(), tiers=len(rast.tiers))
            record("static", timeit(lambda: rast(mi, T, K, out=buf), args.iters, args.warmup, sync), extra)
            if device.type == "cuda":
                g = torch.cuda.CUDAGraph()
                with torch.cuda.graph(g):
                    rast(mi, T, K, out=buf)
                record("static+graph", timeit(g.replay, args.iters, args.warmup, sync), extra)
    for r in rows:
        r["mask_coverage"] = cov
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batch", type=int, default=8, help="samples per training step (B)")
    ap.add_argument("--poses", type=int, default=11, help="poses per sample (history + horizon)")
    ap.add_argument("--cameras", type=int, default=2)
    ap.add_argument("--size", type=int, default=128, help="image size (square)")
    ap.add_argument("--faces", type=int, default=3000, help="face budget of the synthetic mesh")
    ap.add_argument("--shape", default="capsule", choices=["capsule", "icosphere", "gripper"])
    ap.add_argument("--mesh", default=None, help="optional OBJ/STL path (simplified to --faces if possible)")
    ap.add_argument("--cull", action="store_true", help="back-face culling")
    ap.add_argument("--device", default="all", choices=["all", "cpu", "cuda"])
    ap.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: leave as is)")
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--no-static", action="store_true")
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    mesh = build_mesh(args.shape, args.faces, args.mesh)
    devices = []
    if args.device in ("all", "cpu"):
        devices.append(torch.device("cpu"))
    if args.device in ("all", "cuda") and torch.cuda.is_available():
        devices.append(torch.device("cuda"))
    print(f"mesh: {args.mesh or args.shape}, {len(mesh.faces)} faces, {len(mesh.vertices)} vertices; "
          f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads")
    rows = []
    for d in devices:
        rows += bench_device(d, mesh, args)
    if args.out:
        meta = dict(
            args=vars(args), torch=torch.__version__, threads=torch.get_num_threads(), platform=platform.platform(),
            cuda_device=torch.cuda.get_device_name() if torch.cuda.is_available() else None,
        )
        with open(args.out, "w") as f:
            json.dump(dict(meta=meta, results=rows), f, indent=2)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
