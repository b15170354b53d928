#!/usr/bin/env python
"""The first training losses of every shipped R&D config, at fixed seeds: a refactor must not change them.

For each `policies_config/**/rnd*.json` it builds the policy that config describes (its `policy` section, on the
CPU) on the synthetic toy dataset (`lerobot_rnd.testing.record_toy_dataset`, 64x64 images resized to the config's
image size), then takes `--steps` AdamW steps (the config's optimiser preset, no scheduler) on batches drawn at a
fixed seed, and records every step's loss terms.

    python benchmarks/loss_parity.py --out benchmarks/results/loss_parity_before.json      # before a change
    python benchmarks/loss_parity.py --check benchmarks/results/loss_parity_before.json    # after it

`--check` recomputes the losses and fails (exit 1) where any differs from the recorded ones by more than
`--rtol` (relative, default 1e-4) and `--atol`, printing a table either way. bf16 autocast (the CPU tier) is only
bitwise repeatable on one kind of CPU: compare runs made on the same machine.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import torch  # noqa: E402


def shipped_configs() -> list[Path]:
    return sorted((REPO / "policies_config").glob("**/rnd*.json"))


def policy_config(path: Path):
    """The `policy` section of a lerobot-train config file, as an RnDConfig on the CPU."""
    import draccus
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_rnd  # noqa: F401  (registers rnd)
    import lerobot_rnd.sim  # noqa: F401  (registers rnd_mw)

    cfg = draccus.parse(TrainPipelineConfig, str(path), args=[]).policy
    cfg.device = "cpu"
    return cfg


def toy_dataset(root: Path) -> Path:
    try:
        from lerobot_rnd.testing import record_toy_dataset
    except ImportError:  # code from before the toy builder moved into the package (the "before" run of issue 32)
        from tests.toy_data import record_toy_dataset
    return record_toy_dataset(root)


def first_losses(cfg, root: Path, steps: int, batch_size: int) -> list[dict[str, float]]:
    """`steps` AdamW steps of `cfg`'s policy built from scratch on the toy dataset at `root`, at fixed seeds."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.modeling_rnd import RnDPolicy

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    features = dataset_to_policy_features(meta.features)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    torch.manual_seed(0)
    policy = RnDPolicy(cfg, dataset_meta=meta)
    ds = LeRobotDataset("local/toy_reach", root=root, delta_timestamps=resolve_delta_timestamps(cfg, meta))
    items = [ds[i] for i in range(len(ds))]
    data = {k: torch.stack([it[k] for it in items]) for k in items[0] if isinstance(items[0][k], torch.Tensor)}
    optimizer = cfg.get_optimizer_preset().build(policy.get_optim_params())
    order = torch.Generator().manual_seed(0)
    torch.manual_seed(1)  # diffusion steps and noise drawn inside the loss
    policy.train()
    losses = []
    for _ in range(steps):
        idx = torch.randint(0, len(items), (batch_size,), generator=order)
        loss, info = policy.forward({k: v[idx] for k, v in data.items()})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append({"loss": loss.item(), **info})
    return losses


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="write the losses here (JSON)")
    parser.add_argument("--check", type=Path, help="compare with the losses recorded in this JSON")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--batch-size", type=int, default=2)
    parser.add_argument("--rtol", type=float, default=1e-4)
    parser.add_argument("--atol", type=float, default=1e-6)
    parser.add_argument("--only", nargs="*", help="config stems to run (default: every shipped rnd config)")
    args = parser.parse_args(argv)
    if not args.out and not args.check:
        parser.error("give --out (record) and/or --check (compare)")
    torch.set_num_threads(max(1, min(2, os.cpu_count() or 1)))
    reference = json.loads(args.check.read_text()) if args.check else None
    steps = reference["steps"] if reference else args.steps
    batch_size = reference["batch_size"] if reference else args.batch_size
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=REPO).stdout
    result = {"steps": steps, "batch_size": batch_size, "commit": commit.strip(), "torch": torch.__version__,
              "cpu": platform.processor() or platform.machine(), "configs": {}}
    failed = []
    with tempfile.TemporaryDirectory() as tmp:
        root = toy_dataset(Path(tmp) / "toy_reach")
        for path in shipped_configs():
            name = str(path.relative_to(REPO / "policies_config"))
            if args.only and path.stem not in args.only:
                continue
            if reference and name not in reference["configs"]:
                print(f"{name}: not in the reference, skipped")
                continue
            t0 = time.perf_counter()
            losses = first_losses(policy_config(path), root, steps, batch_size)
            seconds = time.perf_counter() - t0
            result["configs"][name] = {"losses": losses, "seconds": round(seconds, 1)}
            worst = 0.0
            if reference:
                for got, want in zip(losses, reference["configs"][name]["losses"], strict=True):
                    if set(got) != set(want):
                        worst = float("inf")
                        break
                    for key, w in want.items():
                        err = abs(got[key] - w)
                        worst = max(worst, err / max(abs(w), 1e-12))
                        if err > args.atol + args.rtol * abs(w):
                            failed.append((name, key))
            status = "" if reference is None else f"  max relative difference {worst:.2e}"
            print(f"{name:40s} first {losses[0]['loss']:.5f}  last {losses[-1]['loss']:.5f}  "
                  f"({seconds:.0f} s){status}", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    if failed:
        print(f"losses differ: {sorted(set(failed))}")
        return 1
    if reference:
        print("every loss matches the reference")
    return 0


if __name__ == "__main__":
    sys.exit(main())
