#!/usr/bin/env python
"""Does a trained policy's action chunk follow the goal, or only the motion already under way? Open loop, on its demos.

A policy can fit its demonstrations on their own frames and still fail in closed loop: with a past frame in its
input it can continue the motion the history shows instead of reading where the goal is (the "copycat" problem,
Wen et al. 2020). The two differ at the first frame of an episode, where the arm has not moved yet and every demo
starts from the same state: there only the images tell the demos apart.

For each demo episode and each start frame t (``--frames``), the script feeds the policy the recorded
observations (with its own history length), samples ``--draws`` chunks (noise draws for diffusion policies), and
compares the joint target at the end of the executed part of the chunk (``n_action_steps``) with the demo's action
at the same step, both relative to the joint state at t (with ``--delta-actions``, for per-step displacement actions
such as the Panda suite's: the sum of the executed part of the chunk against the sum of the demo's actions over the
same steps). Per start frame and joint it writes the least-squares slope
of predicted on demonstrated displacement across the episodes (1: follows the demos, 0: the same motion for every
goal), the correlation, the mean absolute error and the spread over draws. Any LeRobot policy type loads.

    python benchmarks/chunk_goal_response.py \\
        --policy-path <run>/train/checkpoints/003000/pretrained_model \\
        --dataset-root outputs/benchmark/data/so101_reach-target_random_s0_n10 \\
        --out benchmarks/results/chunk_goal_response_so101_reach.json

With ``--other-task`` (a dataset of two tasks whose scenes look alike, such as the Panda pair ``lift-red-cube`` /
``lift-blue-cube``), every observation is also fed with the other task's string and the same noise: the rows then
add the slopes of that prediction on the demo's own motion (``other_task``) and the mean absolute change the task
string alone makes (``task_effect``, against the spread over draws): about 0 for a policy that ignores the task.

Demo episodes only: no evaluation seed is used.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.files import write_result_json
from benchmarks.trace_rollouts import parse_policy_args


def response_stats(pred: np.ndarray, demo: np.ndarray) -> dict:
    """pred (E, D) and demo (E, D) displacements over E episodes -> per-joint slope, correlation, MAE (lists)."""
    slope, corr = [], []
    for j in range(demo.shape[1]):
        x, y = demo[:, j] - demo[:, j].mean(), pred[:, j] - pred[:, j].mean()
        sxx = float((x * x).sum())
        slope.append(float((x * y).sum() / sxx) if sxx > 1e-12 else None)
        syy = float((y * y).sum())
        corr.append(float((x * y).sum() / np.sqrt(sxx * syy)) if sxx > 1e-12 and syy > 1e-12 else None)
    return {"slope": slope, "correlation": corr, "mean_abs_error": np.abs(pred - demo).mean(0).tolist(),
            "demo_displacement_std": demo.std(0).tolist()}  # fmt: skip


def frame_batch(frame: dict, draws: int, past: list[dict] | None = None, task: str | None = None) -> dict:
    """One dataset frame's observations as a batch of `draws` copies, (draws, ...) per key; with `past` (the
    frames oldest first, `frame` last), each key stacked over them: (draws, H, ...). `task`: the task string fed
    (default: the frame's own)."""
    batch = {}
    for key, value in frame.items():
        if key.startswith("observation."):
            x = torch.stack([f[key] for f in past]) if past else value
            batch[key] = x[None].expand(draws, *x.shape).clone()
    batch["task"] = [frame["task"] if task is None else task] * draws
    return batch


def predict_chunk(policy, pre, past: list[dict], draws: int, task: str | None = None) -> torch.Tensor:
    """`draws` normalised action chunks (draws, T, A) for the dataset frames `past` (oldest first, as many as the
    policy's history), fed `task` (default: the frames' own). Diffusion Policy reads its history from the
    observation queue its `select_action` fills (and returns only the executed part of its horizon), so its frames go
    through that queue one by one, as in a rollout; R&D and ACT take them stacked in the batch (R&D) or the current
    one alone (ACT)."""
    if policy.config.type != "diffusion":
        return policy.predict_action_chunk(pre(frame_batch(past[-1], draws, past if len(past) > 1 else None, task)))
    from lerobot.policies.utils import populate_queues
    from lerobot.utils.constants import OBS_IMAGES

    policy.reset()
    for frame in past:
        batch = {k: v for k, v in pre(frame_batch(frame, draws, task=task)).items() if k != "action"}  # as select_action
        if policy.config.image_features:
            batch[OBS_IMAGES] = torch.stack([batch[k] for k in policy.config.image_features], dim=-4)
        policy._queues = populate_queues(policy._queues, batch)
    return policy.predict_action_chunk(batch)


def add_demo_frame_args(p: argparse.ArgumentParser, policy_help: str = "a pretrained_model folder") -> None:
    """The arguments every open-loop probe on a checkpoint's own demos takes: --policy-path, --dataset-root,
    --repo-id, --frames."""
    p.add_argument("--policy-path", required=True, help=policy_help)
    p.add_argument("--dataset-root", required=True, help="the LeRobot dataset the policy was trained on")
    p.add_argument("--repo-id", default=None, help="the dataset's repo id (default: local/<folder name>)")
    p.add_argument("--frames", default="0,8,16", help="start frames within each episode, comma-separated")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_demo_frame_args(p)
    p.add_argument("--draws", type=int, default=8, help="chunks sampled per observation")
    p.add_argument("--seed", type=int, default=0, help="torch seed of the noise draws")
    p.add_argument("--still-history", action="store_true",
                   help="feed the current frame as every past frame too (no motion in the history): if the slopes "
                        "drop, the policy was reading the motion rather than the goal")
    p.add_argument("--delta-actions", action="store_true",
                   help="the actions are per-step displacements (the Panda suite's ee_delta): compare the sum of the "
                        "executed part of the chunk with the sum of the demo's actions over the same steps, instead "
                        "of the joint target at its end minus the state")
    p.add_argument("--other-task", action="store_true",
                   help="a dataset of two tasks: also feed every observation the other task's string (same noise) "
                        "and report how much the prediction changes and whom it follows")
    p.add_argument("--policy-arg", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a sampler setting of the loaded config, e.g. num_inference_steps=4 (repeatable; "
                        "as trace_rollouts.py)")
    p.add_argument("--out", required=True, help="JSON to write")
    a = p.parse_args(argv)

    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.policies.factory import make_policy, make_pre_post_processors

    import lerobot_rnd  # noqa: F401  (registers the rnd policy)

    root = Path(a.dataset_root)
    ds = LeRobotDataset(a.repo_id or f"local/{root.name}", root=root)
    cfg = PreTrainedConfig.from_pretrained(a.policy_path)
    cfg.pretrained_path = a.policy_path
    try:
        cfg = parse_policy_args(cfg, a.policy_arg)
    except ValueError as e:
        p.error(str(e))
    policy = make_policy(cfg=cfg, ds_meta=ds.meta)
    policy.eval()
    pre, post = make_pre_post_processors(policy_cfg=cfg, pretrained_path=a.policy_path)
    history = int(getattr(cfg, "n_obs_steps", 1) or 1)
    k_end = int(cfg.n_action_steps) - 1
    frames = [int(x) for x in a.frames.split(",")]
    torch.manual_seed(a.seed)
    task_names = list(ds.meta.tasks.sort_values("task_index").index) if ds.meta.tasks is not None else []
    if a.other_task and len(task_names) != 2:
        p.error(f"--other-task needs a dataset of exactly two tasks; {root} has {len(task_names)}: {task_names}")

    def displacement(chunk: torch.Tensor, start: int, stop: int, t0: int, now: dict):
        """(draws, A) predicted and (A,) demonstrated displacement over the executed part of the chunk."""
        if a.delta_actions:
            executed = chunk[:, : k_end + 1]  # (draws, K, A)
            steps = post(executed.reshape(-1, executed.shape[-1])).float().cpu().numpy()
            moved = steps.reshape(a.draws, k_end + 1, -1).sum(1)  # (draws, A)
            return moved, np.sum([ds[min(start + t0 + k, stop - 1)]["action"].numpy() for k in range(k_end + 1)], 0)
        state = now["observation.state"].numpy()
        action = post(chunk[:, k_end]).float().cpu().numpy()  # (draws, A) in the dataset's units
        return action - state, ds[min(start + t0 + k_end, stop - 1)]["action"].numpy() - state

    episodes = ds.meta.episodes
    rows = []
    for t0 in frames:
        preds, demos, spreads, others = [], [], [], []
        for e in range(ds.num_episodes):
            start, stop = int(episodes[e]["dataset_from_index"]), int(episodes[e]["dataset_to_index"])
            if start + t0 >= stop:
                continue
            lags = [0] * history if a.still_history else list(range(history - 1, -1, -1))
            past = [ds[start + max(t0 - h, 0)] for h in lags]  # oldest first
            now = past[-1]
            rng = torch.get_rng_state()
            with torch.no_grad():
                chunk = predict_chunk(policy, pre, past, a.draws)  # (draws, T, A), normalised
            moved, demo_moved = displacement(chunk, start, stop, t0, now)
            preds.append(moved.mean(0))
            demos.append(demo_moved)
            spreads.append(moved.std(0))
            if a.other_task:
                torch.set_rng_state(rng)  # the same noise: only the task string differs
                other = next(t for t in task_names if t != now["task"])
                with torch.no_grad():
                    chunk = predict_chunk(policy, pre, past, a.draws, task=other)
                others.append(displacement(chunk, start, stop, t0, now)[0].mean(0))
        pred, demo = np.array(preds), np.array(demos)
        rows.append({"start_frame": t0, "episodes": len(preds), **response_stats(pred, demo),
                     "draw_std": np.mean(spreads, axis=0).tolist()})  # fmt: skip
        if a.other_task:
            rows[-1]["other_task"] = response_stats(np.array(others), demo)
            rows[-1]["task_effect"] = np.abs(pred - np.array(others)).mean(0).tolist()

    names = ds.meta.features["action"].get("names") or [f"a{i}" for i in range(len(rows[0]["slope"]))]
    print(f"policy {a.policy_path} ({cfg.type}, history {history}, chunk end at step {k_end}); "
          f"{ds.num_episodes} demo episodes")  # fmt: skip
    print("slope of predicted on demonstrated displacement (1: follows the demos, 0: one motion for every goal)")
    print("frame  " + "  ".join(f"{n[:12]:>12}" for n in names))
    for r in rows:
        cells = ["{:>12}".format("-" if s is None else f"{s:.2f}") for s in r["slope"]]
        print(f"{r['start_frame']:>5}  " + "  ".join(cells))
        if a.other_task:
            cells = ["{:>12}".format("-" if s is None else f"{s:.2f}") for s in r["other_task"]["slope"]]
            print("other  " + "  ".join(cells) + "   (fed the other task's string)")
            print("effect " + "  ".join(f"{e:>12.4f}" for e in r["task_effect"]) + "   (mean |own - other|; "
                  "draw spread " + " ".join(f"{d:.4f}" for d in r["draw_std"]) + ")")
    write_result_json(Path(a.out), {
        "benchmark": "chunk_goal_response", "policy_path": a.policy_path, "policy_type": cfg.type,
        "dataset_root": str(root), "n_obs_steps": history, "n_action_steps": int(cfg.n_action_steps),
        "draws": a.draws, "seed": a.seed, "still_history": a.still_history, "delta_actions": a.delta_actions,
        "other_task": a.other_task, "tasks": task_names,
        "policy_args": a.policy_arg, "joint_names": names, "rows": rows,
    }, argv, script="benchmarks/chunk_goal_response.py")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
