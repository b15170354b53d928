#!/usr/bin/env python
"""Inference speed of R&D next to LeRobot's ACT and Diffusion Policy, on the same inputs.

Times one action-chunk inference (`predict_action_chunk`, batch 1 by default) of

  * R&D-AI, paper size (RnDConfig defaults: 8 layers, width 1024, 16 heads, patch 16, 128x128, H=2, T=8,
    4 DDIM steps + the final action-space step) and a CPU size (width 256, 4 layers, 8 heads);
  * LeRobot's ACT (chunk 8) and Diffusion Policy (DDIM, 10 steps; DDPM-100 with --ddpm),

all with two 128x128 cameras (`observation.images.front` / `.wrist`), a 4-D `observation.state` and a 4-D
`action`, untrained weights and no downloads (`pretrained_backbone_weights=None`). ACT and Diffusion Policy
are timed on already-normalised random tensors (their normalisers live in the processors). R&D is built on
the toy embodiment of lerobot_rnd/testing.py (a two-finger box gripper, one static and one wrist camera) and
gets a plausible action range (+-8 cm, +-0.3 rad) so the noisy grippers land in the images as they do on a
real task; `--rnd-stats identity` keeps the untrained default (+-1 m, +-1 rad) instead.

Timing: warm-up calls, then `--repeats` calls per method, interleaved round-robin over the methods so that
load from other processes hits them alike; median and p90 per chunk, `torch.no_grad()`, CUDA synchronised.
For R&D a second pass splits one chunk into rendering (`RnDModel.render_frames`), network
(`RnDDenoiser.forward`), SVD (`register_point_update`) and the rest, by wrapping those calls with timers.

    python benchmarks/bench_inference.py                      # CPU (and CUDA if available), ~5 min on 2 cores
    python benchmarks/bench_inference.py --device cuda --repeats 20 --warmup 3 \
        --out benchmarks/results/inference_cuda.json
    python benchmarks/bench_inference.py --configs cpu --compile   # + R&D with inference_compile=True
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.utils import populate_queues
from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

CAMERAS = ("observation.images.front", "observation.images.wrist")
IMAGE_SIZE = (128, 128)
STATE_DIM = 4
ACTION_DIM = 4
N_OBS_STEPS = 2
CHUNK = 8

CPU_TIER_JSON = REPO_ROOT / "policies_config" / "metaworld" / "rnd_ai_cpu.json"
# Keys of a policies_config JSON's "policy" section that are about deployment or the dataset, not the model: the
# benchmark sets its own (device, observation history and chunk come from the constants above).
NOT_MODEL_KEYS = ("type", "device", "push_to_hub", "n_obs_steps", "chunk_size", "n_action_steps", "image_size")


def policy_config_overrides(path: Path = CPU_TIER_JSON) -> dict:
    """The RnDConfig fields a policies_config JSON sets (its "policy" section without NOT_MODEL_KEYS), so the
    benchmark times the CPU tier that `lerobot-train --config_path=...` trains, not a copy that drifts."""
    policy = json.loads(path.read_text())["policy"]
    return {k: v for k, v in policy.items() if k not in NOT_MODEL_KEYS}


RND_CONFIGS = {
    "paper": {},  # RnDConfig defaults
    # policies_config/metaworld/rnd_ai_cpu.json as it is now (patch 32, gripper patches, bf16, its patch_embed).
    "cpu": policy_config_overrides(),
    "cpu_legacy": {"dim_model": 256, "n_layers": 4, "n_heads": 8},  # the CPU config before the CPU tier
}


def describe_rnd(name: str, cfg) -> str:
    from lerobot_rnd.precision import bf16_autocast_applies

    return (
        f"{name}: {cfg.variant}, {cfg.n_layers}L x {cfg.dim_model}, {cfg.n_heads} heads, "
        f"patch {cfg.patch_size} ({cfg.patch_embed})"
        f"{f', {cfg.gripper_patches} gripper patches' if cfg.gripper_patches else ''}"
        f"{', bf16' if cfg.autocast_bf16 and bf16_autocast_applies(torch.device(cfg.device or 'cpu').type) else ''}, "
        f"{cfg.num_inference_steps} DDIM + {int(cfg.final_action_step)} final"
    )


def features():
    inputs = {key: PolicyFeature(type=FeatureType.VISUAL, shape=(3, *IMAGE_SIZE)) for key in CAMERAS}
    inputs[OBS_STATE] = PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,))
    outputs = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,))}
    return inputs, outputs


def n_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


# ----------------------------------------------------------------------------------------------------------
# Builders: each returns (policy, call) where call() runs one chunk inference.
def build_rnd(size: str, device: str, batch: int, embodiment_json: str, stats: str, compile_: bool = False):
    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy

    cfg = RnDConfig(
        device=device, embodiment=embodiment_json, inference_compile=compile_, **RND_CONFIGS[size]
    )
    cfg.input_features, cfg.output_features = features()
    policy = RnDPolicy(cfg).to(device).eval()
    if stats == "toy":
        lo = torch.tensor([-0.08] * 3 + [-0.3] * 3)
        policy.model.action_stats.set(lo, -lo)
    g = torch.Generator().manual_seed(0)
    obs = {key: torch.rand(batch, N_OBS_STEPS, 3, *IMAGE_SIZE, generator=g).to(device) for key in CAMERAS}
    state = torch.tensor([0.0, 0.0, 0.2, 1.0]) + torch.cat(
        [0.03 * torch.randn(batch, 3, generator=g), torch.zeros(batch, 1)], dim=1
    )
    obs[OBS_STATE] = state[:, None].repeat(1, N_OBS_STEPS, 1).to(device)
    noise = torch.randn(batch, cfg.chunk_size, 6, generator=g).to(device)

    def call():
        return policy.predict_action_chunk(obs, noise=noise)

    return policy, call


def build_act(device: str, batch: int):
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy

    cfg = ACTConfig(device=device, chunk_size=CHUNK, n_action_steps=CHUNK, pretrained_backbone_weights=None)
    cfg.input_features, cfg.output_features = features()
    policy = ACTPolicy(cfg).to(device).eval()
    g = torch.Generator().manual_seed(0)
    obs = {key: torch.randn(batch, 3, *IMAGE_SIZE, generator=g).to(device) for key in CAMERAS}
    obs[OBS_STATE] = torch.randn(batch, STATE_DIM, generator=g).to(device)

    def call():
        with torch.no_grad():
            return policy.predict_action_chunk(obs)

    return policy, call


def build_dp(device: str, batch: int, scheduler: str, steps: int):
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    # The U-Net downsamples 3 times: horizon must be a multiple of 8, and LeRobot keeps the actions
    # [n_obs_steps - 1, n_obs_steps - 1 + n_action_steps) of the horizon, so 8 executed actions with 2
    # observations need horizon >= 9 -> 16 (LeRobot's default).
    cfg = DiffusionConfig(
        device=device,
        n_obs_steps=N_OBS_STEPS,
        horizon=16,
        n_action_steps=CHUNK,
        noise_scheduler_type=scheduler,
        num_inference_steps=steps,
        pretrained_backbone_weights=None,
    )
    cfg.input_features, cfg.output_features = features()
    policy = DiffusionPolicy(cfg).to(device).eval()
    g = torch.Generator().manual_seed(0)
    frame = {key: torch.randn(batch, 3, *IMAGE_SIZE, generator=g).to(device) for key in CAMERAS}
    frame[OBS_STATE] = torch.randn(batch, STATE_DIM, generator=g).to(device)
    frame[OBS_IMAGES] = torch.stack([frame[key] for key in CAMERAS], dim=-4)
    policy.reset()
    for _ in range(N_OBS_STEPS):  # fill the observation queues as select_action would
        policy._queues = populate_queues(policy._queues, frame)

    def call():
        with torch.no_grad():
            return policy.predict_action_chunk(frame)

    return policy, call


# ----------------------------------------------------------------------------------------------------------
def rnd_breakdown(policy, call, device: str, runs: int) -> dict:
    """Split one R&D chunk into render / network / SVD / rest by wrapping the calls with timers."""
    import lerobot_rnd.modeling_rnd as modeling

    model = policy.model
    acc = {"render": 0.0, "network": 0.0, "svd": 0.0}
    counts = {"render": 0, "network": 0, "svd": 0}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            sync(device)
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            sync(device)
            acc[name] += time.perf_counter() - t0
            counts[name] += 1
            return out

        return wrapper

    original_register = modeling.register_point_update
    model.render_frames = timed("render", model.render_frames)
    model.network.forward = timed("network", model.network.forward)
    modeling.register_point_update = timed("svd", original_register)
    try:
        total = 0.0
        for _ in range(runs):
            sync(device)
            t0 = time.perf_counter()
            call()
            sync(device)
            total += time.perf_counter() - t0
    finally:
        del model.render_frames
        del model.network.forward
        modeling.register_point_update = original_register
    out = {f"{k}_ms": 1e3 * v / runs for k, v in acc.items()}
    out["total_ms"] = 1e3 * total / runs
    out["other_ms"] = out["total_ms"] - sum(out[f"{k}_ms"] for k in acc)
    out["calls_per_chunk"] = {k: v // runs for k, v in counts.items()}
    return out


def machine_info(devices: list[str]) -> dict:
    import lerobot

    from lerobot_rnd.precision import cpu_bf16_is_fast

    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info = {
        "torch": torch.__version__,
        "lerobot": getattr(lerobot, "__version__", "?"),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu,
        "os_cpu_count": os.cpu_count(),
        "sched_affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "torch_threads": torch.get_num_threads(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "bf16_autocast_applies_on_cpu": cpu_bf16_is_fast(),  # else autocast_bf16 configs ran float32 (precision.py)
        "load_average_at_start": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "devices": {},
    }
    for d in devices:
        info["devices"][d] = torch.cuda.get_device_name(0) if d == "cuda" else cpu
    return info


def summarise(times_s: list[float]) -> dict:
    ms = [1e3 * t for t in times_s]
    return {
        "median_ms": statistics.median(ms),
        "p90_ms": float(np.percentile(ms, 90)),
        "min_ms": min(ms),
        "mean_ms": statistics.fmean(ms),
        "times_ms": ms,
    }


def fmt_ms(x: float) -> str:
    return f"{x:,.1f}" if x < 100 else f"{x:,.0f}"


def run_device(device: str, args, embodiment_json: str) -> tuple[list[dict], list[dict]]:
    torch.manual_seed(0)
    entries = []  # (method, config, policy, call, params)
    print(f"\n[{device}] building policies ...", flush=True)
    act, act_call = build_act(device, args.batch)
    entries.append(
        ("ACT", f"chunk {CHUNK}, ResNet18, 4+1 enc layers + 1 dec, dim 512", act, act_call, n_params(act))
    )
    dp, dp_call = build_dp(device, args.batch, "DDIM", 10)
    entries.append(
        ("Diffusion Policy", "DDIM 10 steps, U-Net (512,1024,2048), horizon 16", dp, dp_call, n_params(dp))
    )
    if args.ddpm:
        dp100, dp100_call = build_dp(device, args.batch, "DDPM", 100)
        entries.append(
            (
                "Diffusion Policy",
                "DDPM 100 steps, U-Net (512,1024,2048), horizon 16",
                dp100,
                dp100_call,
                n_params(dp100),
            )
        )
    rnd_policies = {}
    for size in args.configs:
        pol, call = build_rnd(size, device, args.batch, embodiment_json, args.rnd_stats)
        rnd_policies[size] = (pol, call)
        entries.append(("R&D-AI", describe_rnd(size, pol.config), pol, call, n_params(pol)))

    times = {i: [] for i in range(len(entries))}
    cpu_times = {i: [] for i in range(len(entries))}
    for i, (method, config, _, call, _) in enumerate(entries):
        t0 = time.perf_counter()
        for _ in range(args.warmup):
            call()
        sync(device)
        print(f"  warm-up {method} [{config.split(':')[0]}]: {time.perf_counter() - t0:.1f} s", flush=True)
    for r in range(args.repeats):
        for i, (method, config, _, call, _) in enumerate(entries):
            sync(device)
            t0, c0 = time.perf_counter(), time.process_time()
            call()
            sync(device)
            times[i].append(time.perf_counter() - t0)
            cpu_times[i].append(time.process_time() - c0)
        print(f"  repeat {r + 1}/{args.repeats} done", flush=True)

    results = []
    for i, (method, config, _, _, params) in enumerate(entries):
        results.append(
            {
                "method": method,
                "config": config,
                "device": device,
                "batch": args.batch,
                "params": params,
                **summarise(times[i]),
                "cpu_median_ms": 1e3 * statistics.median(cpu_times[i]),
            }
        )
    act_median = results[0]["median_ms"]
    for res in results:
        res["ratio_to_act"] = res["median_ms"] / act_median

    breakdowns = []
    if not args.no_breakdown:
        for size, (pol, call) in rnd_policies.items():
            bd = rnd_breakdown(pol, call, device, runs=args.breakdown_runs)
            bd.update({"config": size, "device": device})
            breakdowns.append(bd)
            print(f"  breakdown R&D {size}: {bd}", flush=True)

    if args.compile:
        for size in args.configs:
            pol, call = build_rnd(size, device, args.batch, embodiment_json, args.rnd_stats, compile_=True)
            t0 = time.perf_counter()
            call()
            sync(device)
            first = time.perf_counter() - t0
            print(f"  compile R&D {size}: first call {first:.1f} s", flush=True)
            for _ in range(max(0, args.warmup - 1)):
                call()
            ts, cs = [], []
            for _ in range(args.repeats):
                sync(device)
                t0, c0 = time.perf_counter(), time.process_time()
                call()
                sync(device)
                ts.append(time.perf_counter() - t0)
                cs.append(time.process_time() - c0)
            res = {
                "method": "R&D-AI (inference_compile)",
                "config": describe_rnd(size, pol.config),
                "device": device,
                "batch": args.batch,
                "params": n_params(pol),
                "first_call_s": first,
                **summarise(ts),
                "cpu_median_ms": 1e3 * statistics.median(cs),
            }
            res["ratio_to_act"] = res["median_ms"] / act_median
            results.append(res)
    return results, breakdowns


def markdown(results: list[dict], breakdowns: list[dict]) -> str:
    lines = [
        (
            "| method | config | device | params | median ms | p90 ms | min ms | x ACT (median) "
            "| process CPU ms |"
        ),
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in results:
        lines.append(
            f"| {r['method']} | {r['config']} | {r['device']} | {r['params'] / 1e6:.1f} M | "
            f"{fmt_ms(r['median_ms'])} | {fmt_ms(r['p90_ms'])} | {fmt_ms(r['min_ms'])} | "
            f"{r['ratio_to_act']:.1f} | "
            f"{fmt_ms(r['cpu_median_ms'])} |"
        )
    if any("first_call_s" in r for r in results):
        lines.append("")
        for r in results:
            if "first_call_s" in r:
                lines.append(
                    f"- {r['method']} {r['config'].split(':')[0]} ({r['device']}): first call "
                    f"(compilation) {r['first_call_s']:.1f} s"
                )
    if breakdowns:
        lines += [
            "",
            (
                "| R&D config | device | render ms | network ms | SVD ms | other ms | total ms "
                "| calls per chunk (render / network / SVD) |"
            ),
            "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- |",
        ]
        for b in breakdowns:
            c = b["calls_per_chunk"]
            lines.append(
                f"| {b['config']} | {b['device']} | {fmt_ms(b['render_ms'])} | {fmt_ms(b['network_ms'])} | "
                f"{fmt_ms(b['svd_ms'])} | {fmt_ms(b['other_ms'])} | {fmt_ms(b['total_ms'])} | "
                f"{c['render']} / {c['network']} / {c['svd']} |"
            )
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--device",
        choices=["cpu", "cuda"],
        default=None,
        help="default: cpu and cuda if CUDA is available, else cpu",
    )
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--warmup", type=int, default=1)
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    parser.add_argument("--configs", nargs="+", choices=list(RND_CONFIGS), default=["paper", "cpu"])
    parser.add_argument(
        "--rnd-stats",
        choices=["toy", "identity"],
        default="toy",
        help="R&D action range: toy = +-8 cm / +-0.3 rad, identity = untrained default +-1",
    )
    parser.add_argument("--ddpm", action="store_true", help="also time Diffusion Policy with DDPM, 100 steps")
    parser.add_argument("--compile", action="store_true", help="also time R&D with inference_compile=True")
    parser.add_argument("--no-breakdown", action="store_true")
    parser.add_argument("--breakdown-runs", type=int, default=1)
    parser.add_argument("--out", default=str(REPO_ROOT / "benchmarks/results/inference_cpu.json"))
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.device is None:
        devices = ["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"]
    else:
        devices = [args.device]
    if "cuda" in devices and not torch.cuda.is_available():
        parser.error("--device cuda but CUDA is not available")

    from lerobot_rnd.testing import toy_embodiment

    info = machine_info(devices)
    print(json.dumps({k: v for k, v in info.items() if k != "devices"}), flush=True)
    all_results, all_breakdowns = [], []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        embodiment_json = str(toy_embodiment(image_size=IMAGE_SIZE).save_json(Path(tmp) / "toy_128.json"))
        for device in devices:
            results, breakdowns = run_device(device, args, embodiment_json)
            all_results += results
            all_breakdowns += breakdowns
    info["wall_s"] = time.perf_counter() - t_start
    info["load_average_at_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None

    table = markdown(all_results, all_breakdowns)
    print("\n" + table)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "command": "python " + " ".join([os.path.relpath(__file__, REPO_ROOT), *(argv or sys.argv[1:])]),
        "machine": info,
        "args": vars(args),
        "inputs": {
            "cameras": list(CAMERAS),
            "image_size": list(IMAGE_SIZE),
            "state_dim": STATE_DIM,
            "action_dim": ACTION_DIM,
            "n_obs_steps": N_OBS_STEPS,
            "chunk": CHUNK,
        },
        "results": all_results,
        "rnd_breakdown": all_breakdowns,
        "markdown": table,
    }
    out.write_text(json.dumps(payload, indent=2))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
