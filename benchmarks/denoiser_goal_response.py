#!/usr/bin/env python
"""Where does an R&D policy lose the goal: in the network's clean estimate, its image-space path, or the sampler?

`chunk_goal_response.py` measures the sampled chunk against the demos (any policy type). For an R&D checkpoint this
script splits that number into the three things that produce it, on the same demo frames (open loop, no
evaluation seed):

- **action head**: the network's clean estimate a + update at diffusion step k, from a ground-truth chunk noised
  exactly as training noises it (Eq. 1, clamped to [-1, 1]). At k = K - 1 the noisy chunk carries nothing, so
  this row says how well the network reads the goal from the images alone;
- **image path**: the clean estimate the image-space prediction gives at the same k (displacement of the rendered
  gripper's pixels, rigid registration, Eq. 8), as the sampler's first step uses it wherever the gripper is seen;
- **sampler**: the chunk `RnDModel.denoise` returns from pure noise (the checkpoint's own inference steps and
  final action-space pass).

Each row is, per start frame and per dimension of the diffused variable at the chunk's last step (normalised
translation and rotation vector of T_ee_target, or the joints), the least-squares slope of the estimate (mean over
``--draws`` noise draws) on the demo's own value across episodes (1: follows the demos; 0: one answer for every
goal), and the mean absolute error. Dimensions whose demo values hardly vary (std below `MIN_DEMO_STD`) get no
slope.

    python benchmarks/denoiser_goal_response.py \\
        --policy-path outputs/benchmark/panda_random/runs/random/rnd_ai/press-button/n10/seed0/train/checkpoints/003000/pretrained_model \\
        --dataset-root outputs/benchmark/data/panda_press-button_random_s0_n10 \\
        --out benchmarks/results/denoiser_goal_response_panda_press_n10.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.chunk_goal_response import add_demo_frame_args, response_stats
from benchmarks.harness.files import write_result_json

SOURCES = ("action_head", "image_path", "sampler")
#: A dimension whose demo values spread less than this (normalised units, [-1, 1]) gets no slope: it is noise.
MIN_DEMO_STD = 0.02


def demo_window(
    ds, start: int, stop: int, t0: int, history: int, chunk: int
) -> tuple[list[dict], torch.Tensor]:
    """The frames a training window at frame t0 of the episode [start, stop) sees (oldest first, clamped at the
    episode's start) and its action chunk (T, A), clamped at the episode's end, as LeRobot's sampler pads it."""
    past = [ds[start + max(t0 - h, 0)] for h in range(history - 1, -1, -1)]
    actions = torch.stack([ds[min(start + t0 + k, stop - 1)]["action"] for k in range(chunk)])
    return past, actions


@torch.no_grad()
def estimates(
    policy, pre, past: list[dict], actions: torch.Tensor, draws: int, k: int, blank: str | None = None
) -> dict[str, torch.Tensor]:
    """For one demo window: the normalised ground truth and each source's estimate at the chunk's last step,
    {"demo": (D,), "action_head" / "image_path" / "sampler": (D,) mean over draws}. `blank`: a camera key whose
    images (every frame of the window) are replaced by their mean colour, so that camera shows no goal."""
    from lerobot_rnd.sampler import image_space_action

    model = policy.model
    batch = {key: torch.stack([f[key] for f in past])[None].expand(draws, len(past), *past[0][key].shape).clone()
             for key in past[0] if key.startswith("observation.")}  # fmt: skip
    batch["action"] = actions[None].expand(draws, *actions.shape).clone()
    batch["task"] = [past[-1]["task"]] * draws
    batch = pre(batch)
    if blank is not None:
        batch[blank] = torch.full_like(batch[blank], float(batch[blank].mean()))
    batch = policy._stack_images(batch)
    images, state, action = batch["observation.images"], batch["observation.state"], batch["action"]
    images, T_world_ee, gripper = model.prepare_observation(images, state)
    state_now = state[:, -1]
    T_ee_gt, _ = model.action_adapter.to_rnd(action, T_world_ee[:, -1], state=state_now)
    space = model.diffusion_space(state_now)
    a_gt = space.normalize(space.target(action, T_ee_gt))  # (draws, T, D)
    steps = torch.full((draws,), k, dtype=torch.long)
    a_noisy = model.noise_scheduler.add_noise(a_gt, torch.randn_like(a_gt), steps).clamp(-1, 1)
    history = model.render_history(images, T_world_ee)
    history["obs_tokens"] = model.network.embed_observation(history["obs_rgb"], history["obs_points"])
    out = model.denoiser(images, T_world_ee, gripper, history)(a_noisy, space.to_pose(a_noisy), steps, False)
    rows = {"demo": a_gt[0, -1]}
    if out.update is not None:
        rows["action_head"] = (a_noisy + out.update).clamp(-1, 1)[:, -1].mean(0)
    if out.displacement is not None:
        alpha_bar = model.noise_scheduler.alphas_cumprod[k].float()
        a_image, valid = image_space_action(a_noisy, space.to_pose(a_noisy), out, T_world_ee[:, -1:], space,
                                            alpha_bar, torch.tensor(1.0), "x0")  # fmt: skip
        # where too few rendered pixels are seen the sampler falls back to the action head: so does this row
        fallback = (a_noisy + out.update).clamp(-1, 1) if out.update is not None else a_noisy
        rows["image_path"] = torch.where(valid[..., None], a_image, fallback)[:, -1].mean(0)
        rows["image_path_visible"] = valid[:, -1].float().mean()
    a, _ = model.denoise(images, T_world_ee, gripper, torch.randn_like(a_gt), state_now=state_now)
    rows["sampler"] = a[:, -1].mean(0)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_demo_frame_args(p, policy_help="an R&D pretrained_model folder")
    p.add_argument(
        "--step", type=int, default=None, help="diffusion step k of the clean estimates (default K - 1)"
    )
    p.add_argument("--draws", type=int, default=16, help="noise draws per window")
    p.add_argument("--blank-camera", default=None, metavar="KEY",
                   help="feed this camera (e.g. observation.images.wrist) as a uniform grey image: which camera "
                   "does the network read the goal from?")  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="torch seed of the noise draws")
    p.add_argument("--out", required=True, help="JSON to write")
    a = p.parse_args(argv)

    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.policies.factory import make_policy, make_pre_post_processors

    import lerobot_rnd  # noqa: F401  (registers the rnd policy)

    root = Path(a.dataset_root)
    ds = LeRobotDataset(a.repo_id or f"local/{root.name}", root=root)
    cfg = PreTrainedConfig.from_pretrained(a.policy_path)
    if cfg.type != "rnd":
        p.error(f"{a.policy_path} is a {cfg.type!r} policy; this script splits an R&D (rnd) policy's sampler. "
                "Use benchmarks/chunk_goal_response.py for any policy type.")  # fmt: skip
    cfg.pretrained_path = a.policy_path
    policy = make_policy(cfg=cfg, ds_meta=ds.meta)
    policy.eval()
    pre, _ = make_pre_post_processors(policy_cfg=cfg, pretrained_path=a.policy_path)
    if a.blank_camera is not None and a.blank_camera not in cfg.image_features:
        p.error(f"--blank-camera {a.blank_camera!r} is not one of the policy's cameras: {list(cfg.image_features)}")
    k = cfg.num_train_timesteps - 1 if a.step is None else a.step
    if not 0 <= k < cfg.num_train_timesteps:
        p.error(
            f"--step must be in [0, {cfg.num_train_timesteps - 1}] (the checkpoint's num_train_timesteps), got {k}"
        )
    torch.manual_seed(a.seed)
    rows = []
    for t0 in [int(x) for x in a.frames.split(",")]:
        per = {}
        for e in range(ds.num_episodes):
            start, stop = (
                int(ds.meta.episodes[e]["dataset_from_index"]),
                int(ds.meta.episodes[e]["dataset_to_index"]),
            )
            if start + t0 >= stop:
                continue
            past, actions = demo_window(ds, start, stop, t0, int(cfg.n_obs_steps), int(cfg.chunk_size))
            for key, value in estimates(policy, pre, past, actions, a.draws, k, a.blank_camera).items():
                per.setdefault(key, []).append(value.float().cpu().numpy())
        demo = np.array(per["demo"])
        row = {"start_frame": t0, "episodes": len(demo), "demo_std": demo.std(0).tolist()}
        flat = demo.std(0) < MIN_DEMO_STD
        for source in SOURCES:
            if source in per:
                stats = response_stats(np.array(per[source]), demo)
                slope = [None if f else s for s, f in zip(stats["slope"], flat, strict=True)]
                row[source] = {"slope": slope, "mean_abs_error": stats["mean_abs_error"]}
        if "image_path_visible" in per:
            row["image_path_visible"] = float(np.mean(per["image_path_visible"]))
        rows.append(row)

    dims = len(rows[0]["demo_std"])
    print(f"policy {a.policy_path} (variant {cfg.variant}, {cfg.diffusion_space}); clean estimates at k = {k}; "
          f"{ds.num_episodes} demo episodes, {a.draws} draws")  # fmt: skip
    print(
        "slope on the demos' normalised chunk end, per dimension (1: follows the demos, 0: one answer for all)"
    )
    for r in rows:
        for source in SOURCES:
            if source in r:
                cells = " ".join("{:>6}".format("-" if s is None else f"{s:.2f}") for s in r[source]["slope"])
                print(f"frame {r['start_frame']:>3}  {source:<12} {cells}")
    write_result_json(Path(a.out), {
        "benchmark": "denoiser_goal_response", "policy_path": a.policy_path, "dataset_root": str(root),
        "variant": cfg.variant, "diffusion_space": cfg.diffusion_space, "step": k, "blank_camera": a.blank_camera,
        "num_inference_steps": int(cfg.num_inference_steps), "draws": a.draws, "seed": a.seed, "dims": dims,
        "rows": rows,
    }, argv, script="benchmarks/denoiser_goal_response.py")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
