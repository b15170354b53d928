#!/usr/bin/env python
"""How R&D's gripper poses become SO-101 joint targets: inverse kinematics on a 5-joint arm, per orientation weight.

R&D predicts each future gripper pose as a rigid motion; on the SO-101 the ``joint_positions`` action adapter turns
it into joint targets by damped least-squares IK. Five joints cannot reach every rotation, so the IK trades position
against rotation by its ``ik_orientation_weight`` (metres per radian; 1 weighs 1 rad like 1 m). This script takes
the recorded demos' joint targets (poses the arm reached, so reachable), perturbs their poses as a prediction error
would (a rotation of ``--rotation-noise-deg`` about a random axis, a shift of ``--translation-noise-mm`` in a random
direction, each on its own and both together), solves IK from the frame's current joints for every weight, and
reports, per weight and perturbation: the position error to the perturbed target (mm), the rotation error (deg), how
far the joints land from the demo's (deg), and how often pytorch-kinematics converged.

    python benchmarks/so101_ik_study.py --dataset-root outputs/benchmark/data/so101_pick-cube_random_s0_n10 \\
        --out benchmarks/results/so101_ik_study.json
"""

from __future__ import annotations

import argparse
import glob
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

_REPO = Path(__file__).resolve().parents[1]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from benchmarks.harness.files import write_result_json


def load_demo_joints(root: Path, max_frames: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(q_now, q_target) in degrees, (N, 5) each: the state's and the action's body joints of ``max_frames`` frames
    drawn without replacement from the dataset's parquet files."""
    import pandas as pd

    files = sorted(glob.glob(str(root / "data" / "*" / "*.parquet")))
    if not files:
        raise SystemExit(f"no data/*/*.parquet under {root}: --dataset-root takes a LeRobot dataset folder")
    df = pd.concat([pd.read_parquet(f, columns=["observation.state", "action"]) for f in files])
    state = np.stack(df["observation.state"].to_numpy())[:, :5]
    action = np.stack(df["action"].to_numpy())[:, :5]
    rng = np.random.default_rng(seed)
    idx = rng.choice(len(df), size=min(max_frames, len(df)), replace=False)
    return state[idx].astype(np.float64), action[idx].astype(np.float64)


def perturbations(n: int, rot_deg: float, trans_mm: float, seed: int) -> dict[str, np.ndarray]:
    """Rigid perturbations T_target_perturbed (n, 4, 4) in the target's own frame, by name."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed + 1)

    def unit(k):
        v = rng.normal(size=(k, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    R = Rotation.from_rotvec(unit(n) * math.radians(rot_deg)).as_matrix()
    t = unit(n) * trans_mm * 1e-3
    eye = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    rot, shift, both = eye.copy(), eye.copy(), eye.copy()
    rot[:, :3, :3] = R
    shift[:, :3, 3] = t
    both[:, :3, :3], both[:, :3, 3] = R, t
    return {"none": eye, f"rotation {rot_deg:g} deg": rot, f"shift {trans_mm:g} mm": shift,
            f"rotation {rot_deg:g} deg + shift {trans_mm:g} mm": both}  # fmt: skip


def rotation_angle_deg(Ra: torch.Tensor, Rb: torch.Tensor) -> torch.Tensor:
    """Angle of Ra^T Rb (..., 3, 3) in degrees."""
    c = ((Ra.transpose(-1, -2) @ Rb).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    return torch.rad2deg(torch.arccos(c.clamp(-1, 1)))


def study(q_now_deg, q_target_deg, weights, perturbs) -> list[dict]:
    from lerobot_rnd.action_adapters import ActionAdapter
    from lerobot_rnd.so101 import so101_action_adapter

    q_now = torch.deg2rad(torch.as_tensor(q_now_deg))
    q_tgt = torch.deg2rad(torch.as_tensor(q_target_deg))
    rows = []
    for w in weights:
        adapter = ActionAdapter.from_dict(so101_action_adapter(ik_orientation_weight=w))
        T_target = adapter.forward_kinematics(q_tgt)  # (N, 4, 4) base frame
        for name, P in perturbs.items():
            T_goal = T_target @ torch.as_tensor(P)
            t0 = time.perf_counter()
            q, info = adapter.inverse_kinematics(T_goal, q_now)
            seconds = time.perf_counter() - t0
            T_reached = adapter.forward_kinematics(q)
            pos_mm = 1e3 * (T_reached[:, :3, 3] - T_goal[:, :3, 3]).norm(dim=-1)
            rot = rotation_angle_deg(T_reached[:, :3, :3], T_goal[:, :3, :3])
            joint_dev = torch.rad2deg((q - q_tgt).abs().amax(dim=-1))

            def stats(x):
                x = x.double()
                return {"median": float(x.median()), "p90": float(x.quantile(0.9)), "max": float(x.max())}

            rows.append({"orientation_weight": w, "perturbation": name, "frames": len(q),
                         "position_error_mm": stats(pos_mm), "rotation_error_deg": stats(rot),
                         "joint_deviation_from_demo_deg": stats(joint_dev),
                         "converged": float(info["converged"].double().mean()), "ik_seconds": seconds})  # fmt: skip
            print(f"weight {w:<6g} {name:<32} position {rows[-1]['position_error_mm']['median']:7.2f} mm "
                  f"(p90 {rows[-1]['position_error_mm']['p90']:6.2f})  rotation "
                  f"{rows[-1]['rotation_error_deg']['median']:6.2f} deg  joints off demo "
                  f"{rows[-1]['joint_deviation_from_demo_deg']['median']:6.2f} deg  converged "
                  f"{rows[-1]['converged']:.0%}  {seconds:.1f} s", flush=True)  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset-root", required=True, help="an SO-101 LeRobot dataset (lerobot-rnd-record --suite so101)")
    p.add_argument("--weights", default="1,0.3,0.1,0.03", help="ik_orientation_weight values (m/rad)")
    p.add_argument("--rotation-noise-deg", type=float, default=5.0)
    p.add_argument("--translation-noise-mm", type=float, default=5.0)
    p.add_argument("--frames", type=int, default=400, help="frames drawn from the dataset")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", help="JSON file to write")
    a = p.parse_args(argv)
    weights = [float(w) for w in a.weights.split(",") if w]
    q_now, q_target = load_demo_joints(Path(a.dataset_root), a.frames, a.seed)
    perturbs = perturbations(len(q_now), a.rotation_noise_deg, a.translation_noise_mm, a.seed)
    torch.set_default_dtype(torch.float64)
    rows = study(q_now, q_target, weights, perturbs)
    if a.out:
        out = {"benchmark": "so101_ik_study", "dataset_root": a.dataset_root, "frames": len(q_now), "seed": a.seed,
               "results": rows}  # fmt: skip
        write_result_json(a.out, out, argv, script="benchmarks/so101_ik_study.py")
    return 0


if __name__ == "__main__":
    sys.exit(main())
