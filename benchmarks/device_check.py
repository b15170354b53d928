#!/usr/bin/env python
"""One prepared GPU check that fits a short device lease (~8 minutes on one GPU), or a CPU smoke run.

Measures, in one process, and writes one JSON (`--out`):

  latency      one action chunk at batch 1: paper-size R&D-AI eager, R&D-AI compiled (`inference_compile`:
               torch.compile "reduce-overhead" = CUDA graphs over static-shape rendering; CUDA only), LeRobot's
               ACT and Diffusion Policy (DDIM 10), interleaved round-robin; ratios R&D / ACT.
  train_step   one training step (forward, backward, AdamW) at batch 32 of paper-size R&D-AI (rendering, targets,
               loss) against the bare ViT of the same size on random tensors (the rendering and target overhead).
  equality     compiled vs eager actions for the same noise (max abs difference, normalised and metres).

    bash benchmarks/device_check.sh                 # on the GPU machine (sets up the carried wheels)
    python benchmarks/device_check.py --smoke       # CPU, tiny sizes, < 2 minutes (run by the test suite)

The target (issue 12): a paper-size R&D-AI chunk no slower than ACT's (ratio <= 1.0) on the GPU.
"""

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

import torch

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))

from bench_inference import (  # noqa: E402
    CAMERAS,
    IMAGE_SIZE,
    N_OBS_STEPS,
    build_act,
    build_dp,
    build_rnd,
    n_params,
    sync,
)

SIZES = {
    # name: (R&D overrides, timing repeats, warm-up calls, training steps timed)
    "paper": ({}, 20, 3, 10),
    "smoke": ({"dim_model": 64, "n_layers": 1, "n_heads": 4}, 2, 1, 2),
}


def time_calls(calls: dict, repeats: int, device: str) -> dict:
    """Round-robin timing of zero-argument callables; returns median/min ms per name."""
    times = {k: [] for k in calls}
    for _ in range(repeats):
        for name, fn in calls.items():
            sync(device)
            t0 = time.perf_counter()
            fn()
            sync(device)
            times[name].append(1e3 * (time.perf_counter() - t0))
    return {k: {"median_ms": statistics.median(v), "min_ms": min(v), "n": len(v)} for k, v in times.items()}


def rnd_training_step(policy, batch_size: int, device: str):
    """A closure running one R&D training step on a synthetic batch (toy embodiment, plausible poses)."""
    g = torch.Generator().manual_seed(0)
    h = N_OBS_STEPS
    t = policy.config.chunk_size
    batch = {key: torch.rand(batch_size, h, 3, *IMAGE_SIZE, generator=g).to(device) for key in CAMERAS}
    state = torch.tensor([0.0, 0.0, 0.2, 1.0]) + torch.cat(
        [0.03 * torch.randn(batch_size, 3, generator=g), torch.zeros(batch_size, 1)], dim=1
    )
    batch["observation.state"] = state[:, None].repeat(1, h, 1).to(device)
    action = torch.cat([0.8 * torch.rand(batch_size, t, 3, generator=g) - 0.4, torch.ones(batch_size, t, 1)], -1)
    batch["action"] = action.to(device)
    policy.train()
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-4)

    def step():
        loss, _ = policy.forward(batch)
        loss.backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)

    return step


def bare_vit_step(policy, batch_size: int, device: str):
    """The same ViT (a fresh copy) on random inputs of the shapes R&D feeds it: no rendering, no targets."""
    import copy

    net = copy.deepcopy(policy.model.network).to(device).train()
    cfg = policy.config
    c, h, t = len(CAMERAS), cfg.n_obs_steps, cfg.chunk_size
    g = torch.Generator().manual_seed(1)
    hh, ww = cfg.image_size

    def r(*shape):
        return torch.rand(*shape, generator=g).to(device)

    if cfg.gripper_patches:
        n = cfg.gripper_patches * cfg.patch_size**2
        fut_shape = (batch_size, t, c, 3, n)
        patch_index = torch.arange(cfg.gripper_patches, device=device).expand(batch_size, t, c, -1)
    else:
        fut_shape = (batch_size, t, c, 3, hh, ww)
        patch_index = None
    args = (r(batch_size, h, c, 3, hh, ww), r(batch_size, h, c, 3, hh, ww), r(*fut_shape), r(*fut_shape),
            r(batch_size, h), torch.randint(0, 50, (batch_size,)).to(device), r(batch_size, t, 6))  # fmt: skip
    optimizer = torch.optim.AdamW(net.parameters(), lr=1e-4)
    autocast = policy.model._autocast(device.split(":")[0])

    def step():
        with autocast:
            d, u, logits = net(*args, patch_index=patch_index)
        loss = d.float().abs().mean() + u.float().abs().mean() + logits.float().abs().mean()
        loss.backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)

    return step, n_params(net)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--smoke", action="store_true", help="tiny sizes on CPU: checks the script, measures nothing")
    p.add_argument("--device", default=None, help="default: cuda if available, else cpu")
    p.add_argument("--train-batch", type=int, default=None, help="default 32 (smoke: 2)")
    p.add_argument("--bf16", action="store_true", help="R&D under bf16 autocast (autocast_bf16=True)")
    p.add_argument("--out", default=None, help="default benchmarks/results/device_check_<device>.json")
    a = p.parse_args(argv)
    device = a.device or ("cuda" if torch.cuda.is_available() else "cpu")
    size = "smoke" if a.smoke else "paper"
    overrides, repeats, warmup, train_steps = SIZES[size]
    overrides = {**overrides, "autocast_bf16": a.bf16}
    train_batch = a.train_batch or (2 if a.smoke else 32)
    out_path = Path(a.out or REPO_ROOT / "benchmarks" / "results" / f"device_check_{size}_{device}.json")
    t_start = time.time()
    result = {
        "check": "device_check", "size": size, "device": device,
        "device_name": torch.cuda.get_device_name(0) if device.startswith("cuda") else platform.processor(),
        "torch": torch.__version__, "python": platform.python_version(),
        "command": " ".join([sys.executable, *sys.argv]), "rnd_overrides": overrides,
    }  # fmt: skip

    def save():
        result["wall_s"] = round(time.time() - t_start, 1)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps(result, indent=1))

    import bench_inference

    bench_inference.RND_CONFIGS[size] = overrides
    from lerobot_rnd.testing import toy_embodiment

    with tempfile.TemporaryDirectory() as tmp:
        emb = str(toy_embodiment(image_size=IMAGE_SIZE).save_json(Path(tmp) / "toy_128.json"))
        torch.manual_seed(0)
        print(f"[{device}] building R&D-AI ({size}), ACT, Diffusion Policy ...", flush=True)
        rnd, rnd_call = build_rnd(size, device, 1, emb, "toy")
        act, act_call = build_act(device, 1)
        dp, dp_call = build_dp(device, 1, "DDIM", 10)
        calls = {"rnd_ai_eager": rnd_call, "act": act_call, "diffusion_ddim10": dp_call}
        result["parameters"] = {"rnd_ai": n_params(rnd), "act": n_params(act), "diffusion": n_params(dp)}
        compiled = None
        if device.startswith("cuda"):
            rnd_c, rnd_c_call = build_rnd(size, device, 1, emb, "toy", compile_=True)
            rnd_c.load_state_dict(rnd.state_dict())
            t0 = time.time()
            rnd_c_call()  # first call compiles
            result["compile_s"] = round(time.time() - t0, 1)
            calls["rnd_ai_compiled"] = rnd_c_call
            compiled = rnd_c
        else:
            result["compiled"] = "skipped: inference_compile applies on CUDA only"
        for fn in calls.values():
            for _ in range(warmup):
                fn()
        lat = time_calls(calls, repeats, device)
        act_ms = lat["act"]["median_ms"]
        for k in lat:
            lat[k]["ratio_to_act"] = lat[k]["median_ms"] / act_ms
        result["latency_batch1"] = lat
        print(json.dumps({k: round(v["median_ms"], 2) for k, v in lat.items()}), flush=True)
        save()

        if compiled is not None:  # same weights, observation and noise (both builders seed their inputs with 0)
            diff = (rnd_c_call() - rnd_call()).abs().max().item()
            result["equality"] = {"max_abs_action_diff": diff, "units": "dataset actions (toy: 4-D, 1 = 1 cm)",
                                  "pass": diff < 1e-2}  # fmt: skip
            save()
        del act, dp, calls
        if device.startswith("cuda"):
            torch.cuda.empty_cache()

        print(f"[{device}] training step at batch {train_batch} ...", flush=True)
        step = rnd_training_step(rnd, train_batch, device)
        vit_step, vit_params = bare_vit_step(rnd, train_batch, device)
        for _ in range(warmup):
            step()
            vit_step()
        tr = time_calls({"rnd_ai": step, "bare_vit": vit_step}, train_steps, device)
        tr["rnd_ai"]["ratio_to_bare_vit"] = tr["rnd_ai"]["median_ms"] / tr["bare_vit"]["median_ms"]
        result["train_step"] = {"batch": train_batch, "bare_vit_parameters": vit_params, **tr}
        print(json.dumps({k: round(v["median_ms"], 2) for k, v in tr.items()}), flush=True)
    save()
    print(f"wrote {out_path} in {result['wall_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
