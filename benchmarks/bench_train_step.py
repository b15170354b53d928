#!/usr/bin/env python
"""Where one training step goes: R&D's CPU configs next to ACT and Diffusion Policy, in one process.

For every method it builds the policy, its pre-processor, the optimiser and the LeRobot dataset exactly as
`lerobot-train --config_path=policies_config/metaworld/<method>.json` does, then times, per step,

  data     one batch from the dataset (`DataLoader`, num_workers=0: the pure cost; lerobot-train hides part of
           it behind the model with worker processes, which share the same cores)
  pre      the pre-processor (normalisation, device)
  render   R&D only: rasterising the gripper (`RnDModel.render_frames`, inside `forward`)
  forward  `policy.forward` minus rendering
  backward `loss.backward()`
  optim    gradient clipping, `optimizer.step()`, `zero_grad`, and `policy.update()` (EMA) if defined

and, outside the step's total, `data_upstream`: one batch of the same dataset read with LeRobot 0.4.4's own frame
query instead of the plugin's column-first one (`lerobot_rnd.dataset_query`), so the table shows what that saves.

Methods are timed round-robin (one step of each in turn, after warm-up steps), so load from other processes
hits them alike; the table reports medians and each method's total relative to the first one
(`--reference`). Results: a printed table and `--out` JSON.

    python benchmarks/bench_train_step.py --dataset-root data/mw_reach-v3_10 \
        --out benchmarks/results/train_step_cpu.json

The dataset: `lerobot-rnd-record --task reach-v3 --episodes 10 --root data/mw_reach-v3_10 --seed 0`.

Other suites: a method `SUITE/NAME` is policies_config/SUITE/NAME.json (a bare NAME is metaworld's), and each suite
gets its own dataset with `--dataset-root SUITE=PATH` (repeatable), e.g. R&D and ACT on the SO-101 next to MetaWorld:

    python benchmarks/bench_train_step.py --methods rnd_ai_cpu,act_cpu,so101/rnd_ai_cpu,so101/act_cpu \
        --dataset-root metaworld=data/mw_reach-v3_10 --dataset-root so101=data/so101_pick-cube_10
"""


import argparse
import contextlib
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("LEROBOT_RND_PATCH_ALL", "1")  # every method reads data the plugin's way, as lerobot-train

import torch

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

from lerobot_rnd.precision import cpu_bf16_is_fast  # noqa: E402

PHASES = ("data", "pre", "render", "forward", "backward", "optim")
DEFAULT_METHODS = "rnd_ai_cpu_legacy,rnd_ai_cpu,act_cpu,diffusion_cpu"


def split_method(name: str) -> tuple[str, str]:
    """'so101/act_cpu' -> ('so101', 'act_cpu'); a bare name is MetaWorld's."""
    suite, _, config = name.rpartition("/")
    return suite or "metaworld", config


def dataset_roots(values: list[str] | None) -> dict[str, str]:
    """`--dataset-root` values -> {suite: path}; a value without 'SUITE=' is the dataset of every suite ('*')."""
    roots = {}
    for v in values or ["data/mw_reach-v3_10"]:
        suite, sep, path = v.partition("=")
        roots.update({suite: path} if sep else {"*": v})
    return roots


def load_train_config(name: str, dataset_root: str, batch_size: int):
    """A TrainPipelineConfig from policies_config/<suite>/<name>.json (`name` = [suite/]config), on CPU."""
    from lerobot.configs import parser
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_policy_rnd  # noqa: F401  (registers --policy.type=rnd)

    suite, config = split_method(name)
    path = REPO_ROOT / "policies_config" / suite / f"{config}.json"
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist: --methods takes [SUITE/]NAME of policies_config/SUITE/NAME.json")
    root = Path(dataset_root).resolve()
    args = [
        f"--config_path={path}",
        f"--dataset.root={root}",
        f"--dataset.repo_id=local/{root.name}",
        f"--batch_size={batch_size}",
        "--policy.device=cpu",
        "--output_dir=/tmp/unused_bench_train_step",
    ]
    def parse(cfg: TrainPipelineConfig):
        return cfg

    with _argv(args):
        cfg = parser.wrap()(parse)()  # draccus parses sys.argv exactly as lerobot-train does
    assert isinstance(cfg, TrainPipelineConfig)
    cfg.validate()
    return cfg


@contextlib.contextmanager
def _argv(args: list[str]):
    old = sys.argv
    sys.argv = ["bench_train_step", *args]
    try:
        yield
    finally:
        sys.argv = old


class Method:
    """One policy with its data, pre-processor and optimiser, stepping like lerobot-train."""

    def __init__(self, name: str, dataset_root: str, batch_size: int, seed: int):
        from lerobot.datasets.factory import make_dataset
        from lerobot.optim.factory import make_optimizer_and_scheduler
        from lerobot.policies.factory import make_policy, make_pre_post_processors

        torch.manual_seed(seed)
        self.name = name
        self.dataset_root = dataset_root
        cfg = load_train_config(name, dataset_root, batch_size)
        self.cfg = cfg
        t0 = time.perf_counter()
        self.dataset = make_dataset(cfg)
        self.policy = make_policy(cfg=cfg.policy, ds_meta=self.dataset.meta)
        self.setup_s = time.perf_counter() - t0
        self.pre, _ = make_pre_post_processors(policy_cfg=cfg.policy, dataset_stats=self.dataset.meta.stats)
        self.optimizer, self.scheduler = make_optimizer_and_scheduler(cfg, self.policy)
        self.grad_clip = cfg.optimizer.grad_clip_norm
        generator = torch.Generator().manual_seed(seed)
        self.loader = torch.utils.data.DataLoader(
            self.dataset, batch_size=batch_size, shuffle=True, num_workers=0, drop_last=True, generator=generator
        )
        self._it = iter(self.loader)
        self.upstream_loader = torch.utils.data.DataLoader(
            self.dataset, batch_size=batch_size, shuffle=True, num_workers=0, drop_last=True,
            generator=torch.Generator().manual_seed(seed + 1),
        )
        self._upstream_it = iter(self.upstream_loader)
        self.upstream_data_s: list[float] = []
        self.n_params = sum(p.numel() for p in self.policy.parameters() if p.requires_grad)
        self.render_s = 0.0
        model = getattr(self.policy, "model", None)
        if model is not None and hasattr(model, "render_frames"):
            original = model.render_frames

            def timed_render(*args, **kwargs):
                t = time.perf_counter()
                out = original(*args, **kwargs)
                self.render_s += time.perf_counter() - t
                return out

            model.render_frames = timed_render
        self.times: dict[str, list[float]] = {p: [] for p in PHASES}
        self.losses: list[float] = []

    def _next(self):
        try:
            return next(self._it)
        except StopIteration:
            self._it = iter(self.loader)
            return next(self._it)

    def time_upstream_batch(self) -> None:
        """Time one batch read with LeRobot's own `_query_hf_dataset` (if the plugin replaced it)."""
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        upstream = getattr(LeRobotDataset, "_upstream_query_hf_dataset", None)
        if upstream is None:
            return
        patched = LeRobotDataset._query_hf_dataset
        LeRobotDataset._query_hf_dataset = upstream
        try:
            t0 = time.perf_counter()
            try:
                next(self._upstream_it)
            except StopIteration:
                self._upstream_it = iter(self.upstream_loader)
                next(self._upstream_it)
            self.upstream_data_s.append(time.perf_counter() - t0)
        finally:
            LeRobotDataset._query_hf_dataset = patched

    def step(self, record: bool) -> None:
        t0 = time.perf_counter()
        batch = self._next()
        t1 = time.perf_counter()
        batch = self.pre(batch)
        t2 = time.perf_counter()
        self.policy.train()
        self.render_s = 0.0
        loss, _ = self.policy.forward(batch)
        t3 = time.perf_counter()
        loss.backward()
        t4 = time.perf_counter()
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.grad_clip)
        self.optimizer.step()
        self.optimizer.zero_grad()
        if self.scheduler is not None:
            self.scheduler.step()
        if hasattr(self.policy, "update"):
            self.policy.update()
        t5 = time.perf_counter()
        if record:
            self.times["data"].append(t1 - t0)
            self.times["pre"].append(t2 - t1)
            self.times["render"].append(self.render_s)
            self.times["forward"].append(t3 - t2 - self.render_s)
            self.times["backward"].append(t4 - t3)
            self.times["optim"].append(t5 - t4)
            self.losses.append(float(loss))
            self.time_upstream_batch()

    def summary(self) -> dict:
        med = {p: statistics.median(v) for p, v in self.times.items()}
        totals = [sum(self.times[p][i] for p in PHASES) for i in range(len(self.times["data"]))]
        pol = self.cfg.policy
        return {
            "method": self.name,
            "dataset_root": self.dataset_root,
            "policy_type": pol.type,
            "parameters": self.n_params,
            "median_s": med,
            "median_total_s": statistics.median(totals),
            "median_data_upstream_s": statistics.median(self.upstream_data_s) if self.upstream_data_s else None,
            "p90_total_s": sorted(totals)[int(0.9 * (len(totals) - 1))],
            "steps_timed": len(totals),
            "setup_s": self.setup_s,
            "loss_first_last": [self.losses[0], self.losses[-1]] if self.losses else None,
            "settings": {
                k: getattr(pol, k)
                for k in ("dim_model", "n_layers", "patch_size", "image_size", "n_obs_steps", "chunk_size",
                          "horizon", "down_dims", "gripper_patches", "patch_embed", "autocast_bf16", "variant")
                if hasattr(pol, k)
            },
        }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset-root", action="append",
                   help="dataset of every method, or SUITE=PATH per suite (repeatable); default data/mw_reach-v3_10")
    p.add_argument("--methods", default=DEFAULT_METHODS,
                   help="[SUITE/]NAME of policies_config/SUITE/NAME.json (SUITE defaults to metaworld)")
    p.add_argument("--reference", default=None, help="method the ratios are relative to (default: the first)")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--steps", type=int, default=6)
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: all cores)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="JSON output path")
    a = p.parse_args(argv)
    if a.threads:
        torch.set_num_threads(a.threads)
    names = [m for m in a.methods.split(",") if m]
    roots = dataset_roots(a.dataset_root)
    methods = []
    for name in names:
        suite = split_method(name)[0]
        root = roots.get(suite, roots.get("*"))
        if root is None:
            p.error(f"no dataset for suite {suite!r} (method {name}): add --dataset-root {suite}=PATH")
        print(f"building {name} on {root} ...", flush=True)
        methods.append(Method(name, root, a.batch_size, a.seed))
    for i in range(a.warmup + a.steps):
        for m in methods:
            m.step(record=i >= a.warmup)
        print(f"step {i + 1}/{a.warmup + a.steps}", flush=True)
    rows = [m.summary() for m in methods]
    ref_name = a.reference or names[0]
    ref = next(r for r in rows if r["method"] == ref_name)
    for r in rows:
        r["speedup_vs_reference"] = ref["median_total_s"] / r["median_total_s"]

    head = f"{'method':<22}{'params':>9}" + "".join(f"{p:>10}" for p in PHASES) + f"{'total':>9}{'x ref':>8}{'data (LeRobot query)':>22}"
    print(f"\nOne training step, batch {a.batch_size}, medians of {a.steps} steps (s); x ref = speed-up over "
          f"{ref_name}\n" + head)
    for r in rows:
        print(
            f"{r['method']:<22}{r['parameters'] / 1e6:>8.1f}M"
            + "".join(f"{r['median_s'][p]:>10.3f}" for p in PHASES)
            + f"{r['median_total_s']:>9.3f}{r['speedup_vs_reference']:>8.2f}"
            + (f"{r['median_data_upstream_s']:>22.3f}" if r["median_data_upstream_s"] is not None else "")
        )
    if a.out:
        out = {
            "benchmark": "train_step",
            "command": "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
            "batch_size": a.batch_size,
            "warmup": a.warmup,
            "steps": a.steps,
            "threads": torch.get_num_threads(),
            "dataset_root": roots["*"] if list(roots) == ["*"] else roots,
            "reference": ref_name,
            "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                        "torch": torch.__version__, "cpu_capability": torch.backends.cpu.get_cpu_capability(),
                        # whether autocast_bf16=True configs really ran in bf16 here (lerobot_rnd/precision.py)
                        "bf16_autocast_applies": cpu_bf16_is_fast()},
            "results": rows,
        }
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps(out, indent=1, default=str))
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
