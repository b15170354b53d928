"""The spatial protocol's evaluation: the grid of evaluation placements (two placement coordinates, or three:
Panda's object x, y and yaw) and lerobot-eval's loop over an explicit list of placements (``run_benchmark.py
_grid_eval``, run as a subprocess: ``rnd_mw``, ``rnd_panda`` and ``rnd_so101`` take no placement list on the command line)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import ENTRY_POINT, REPO_ROOT
from .files import _write_json

GRID_DIMS = {"reach-v3": (3, 4), "reach-wall-v3": (3, 4)}  # goal x, y; other tasks: object x, y


def grid_axis(low: float, high: float, n: int, layout: str = "edges") -> list[float]:
    """``n`` grid values over ``[low, high]``: "edges" (``linspace``: both ends included) or "cells" (the centres
    of ``n`` equal cells: ``low + (i + 0.5) / n * (high - low)``)."""
    import numpy as np

    if layout == "edges":
        return np.linspace(low, high, n).tolist()
    if layout == "cells":
        return (low + (np.arange(n) + 0.5) / n * (high - low)).tolist()
    raise ValueError(f"grid layout must be 'edges' or 'cells', got {layout!r}")


def grid_description(layout: str, others: str, eval_seed: int) -> str:
    """results.json's settings.eval_placements for the spatial protocol."""
    where = ("cell centres of the placement range (G equal cells per coordinate)" if layout == "cells" else
             "G points per coordinate from one end of the placement range to the other")  # fmt: skip
    rest = ("the other coordinates at the centre of their range (a cell whose placement is invalid is skipped)"
            if others == "centre" else
            "the other coordinates (push-block / pick-place: the target x, y) drawn uniformly from their range "
            "until valid with numpy.random.default_rng(eval_seed + cell index) (eval_seed "
            f"{eval_seed}; the recording seed's generator never draws these); a cell with no valid placement is "
            "skipped")  # fmt: skip
    return (f"grid over two or three placement coordinates (eval_sets: grid_dims; third = yaw for Panda), {where}; "
            f"{rest}; one episode per cell, all with the seed eval_seed")


def grid_placements(env, task: str, low, high, grid: int, grid_dims: list[int] | None, eval_seed: int,
                    n_third: int = 1, layout: str = "edges", others: str = "centre") -> dict:  # fmt: skip
    """The valid points of a ``grid`` x ``grid`` grid over two placement coordinates of ``env`` (``grid_dims``,
    else the task's ``GRID_DIMS``, else its first two varying coordinates), or of a ``grid`` x ``grid`` x
    ``n_third`` grid over three (``grid_dims`` of length 3, e.g. Panda's object x, y, yaw); one episode each, all
    with ``eval_seed``.

    ``layout``: "edges" (grid values from one end of the range to the other) or "cells" (cell centres), see
    :func:`grid_axis`. ``others`` (the coordinates not in the grid): "centre" (the centre of their range; a cell
    whose placement is then invalid is skipped) or "seeded" (those that vary drawn uniformly with
    ``numpy.random.default_rng(eval_seed + cell index)`` until valid: ``lerobot_rnd.sim.placements.complete_placement``;
    a cell with no valid placement is skipped). ``cells`` holds [iy, ix] (two dims) or [iy, ix, iz] (three) per
    placement, ``n_invalid`` the cells skipped."""
    import numpy as np

    dims = tuple(grid_dims) if grid_dims else GRID_DIMS.get(task)
    if dims is None:
        varying = [i for i in range(len(low)) if high[i] > low[i]]
        if len(varying) < 2:
            raise ValueError(
                f"--protocol spatial needs two placement coordinates that vary; {task} varies {len(varying)} "
                f"({varying}): use --protocol random for it, or name two coordinates with --grid-dims"
            )
        dims = tuple(varying[:2])
    if others not in ("centre", "seeded"):
        raise ValueError(f"others must be 'centre' or 'seeded', got {others!r}")
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    centre = (low + high) / 2
    xs = grid_axis(low[dims[0]], high[dims[0]], grid, layout)
    ys = grid_axis(low[dims[1]], high[dims[1]], grid, layout)
    zs = grid_axis(low[dims[2]], high[dims[2]], n_third, layout) if len(dims) == 3 else [None]
    points, cells, other_seeds = [], [], []
    index = 0
    for iz, z in enumerate(zs):
        for iy, y in enumerate(ys):
            for ix, x in enumerate(xs):
                p = centre.copy()
                p[dims[0]], p[dims[1]] = x, y
                if z is not None:
                    p[dims[2]] = z
                seed = eval_seed + index
                index += 1
                if others == "seeded":
                    from lerobot_rnd.sim.placements import complete_placement

                    p = complete_placement(env, p, dims, np.random.default_rng(seed))
                    if p is None:
                        continue
                elif not env.is_valid_placement(p):
                    continue
                points.append([float(v) for v in p])
                cells.append([iy, ix] if z is None else [iy, ix, iz])
                other_seeds.append(seed)
    out = {"grid_dims": list(dims), "grid_x": list(xs), "grid_y": list(ys), "placements": points,
           "cells": cells, "n_invalid": index - len(points), "seeds": [eval_seed] * len(points)}  # fmt: skip
    if len(dims) == 3:
        out["grid_z"] = list(zs)
    if layout != "edges":
        out["grid_layout"] = layout
    if others == "seeded":
        out["other_coordinates"] = "seeded"
        out["other_seeds"] = other_seeds
    return out


def grid_eval_argv(ckpt: Path, device: str, task: str, episode_length: int, batch_size: int, seed: int,
                   placements_file: Path, output_dir: Path, env_args: list[str] = (),
                   env_type: str = "rnd_mw") -> list[str]:  # fmt: skip
    """The command that evaluates ``ckpt`` on the placements listed in ``placements_file`` (runs ``main``).

    ``env_args``: lerobot-eval's ``--env.*`` flags for the demos' observations (``recorded_env_args``);
    ``env_type``: rnd_mw, rnd_panda or rnd_so101."""
    return [sys.executable, str(ENTRY_POINT), "_grid_eval",
            f"--policy-path={ckpt}", f"--device={device}", f"--task={task}",
            f"--episode-length={episode_length}", f"--batch-size={batch_size}",
            f"--seed={seed}", f"--placements={placements_file}", f"--output-dir={output_dir}",
            *(f"--env-arg={x}" for x in env_args),
            *([f"--env-type={env_type}"] if env_type != "rnd_mw" else [])]  # fmt: skip


def env_config(task: str, episode_length: int, env_args: list[str], env_type: str = "rnd_mw"):
    """The rnd_mw (or rnd_panda, rnd_so101) env config that lerobot-eval builds from ``--env.task=...
    --env.episode_length=... *env_args``."""
    import draccus

    import lerobot_policy_rnd  # noqa: F401

    if env_type == "rnd_panda":
        from lerobot_rnd.sim.panda_env import RnDPandaEnvConfig as RnDMetaWorldEnvConfig
    elif env_type == "rnd_so101":
        from lerobot_rnd.sim.so101_env import RnDSO101EnvConfig as RnDMetaWorldEnvConfig
    elif env_type == "rnd_mw":
        from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig
    else:
        raise ValueError(f"--env-type must be rnd_mw, rnd_panda or rnd_so101, got {env_type!r}")

    args = [f"--task={task}", f"--episode_length={episode_length}"]
    for x in env_args:
        if not x.startswith("--env."):
            raise ValueError(f"--env-arg takes lerobot-eval's --env.* flags, got {x!r}")
        args.append("--" + x.removeprefix("--env."))
    return draccus.parse(RnDMetaWorldEnvConfig, args=args)


def main(argv: list[str]) -> int:
    """lerobot-eval's loop over an explicit list of placements (one episode each); writes eval_info.json
    in lerobot-eval's layout (per_task[0].metrics.successes)."""
    p = argparse.ArgumentParser(prog="run_benchmark.py _grid_eval")
    p.add_argument("--policy-path", required=True)
    p.add_argument("--device", default="cpu")
    p.add_argument("--task", required=True)
    p.add_argument("--episode-length", type=int, default=300)
    p.add_argument("--batch-size", type=int, default=1)
    p.add_argument("--seed", type=int, default=1000)
    p.add_argument("--placements", required=True)
    p.add_argument("--output-dir", required=True)
    p.add_argument("--env-arg", action="append", default=[], metavar="--env.FIELD=VALUE",
                   help="an --env.* flag of lerobot-eval for the rnd_mw env (the demos' cameras, corner2 position...)")
    p.add_argument("--env-type", default="rnd_mw", choices=["rnd_mw", "rnd_panda", "rnd_so101"])
    a = p.parse_args(argv)
    sys.path.insert(0, str(REPO_ROOT))
    import gymnasium as gym
    import torch
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.policies.factory import make_policy, make_pre_post_processors
    from lerobot.scripts.lerobot_eval import eval_policy
    from lerobot.utils.random_utils import set_seed

    placements = json.loads(Path(a.placements).read_text())
    set_seed(a.seed)
    env_cfg = env_config(a.task, a.episode_length, a.env_arg, a.env_type)
    pcfg = PreTrainedConfig.from_pretrained(a.policy_path)
    pcfg.pretrained_path = Path(a.policy_path)
    pcfg.device = a.device
    policy = make_policy(cfg=pcfg, env_cfg=env_cfg)
    policy.eval()
    pre, post = make_pre_post_processors(
        policy_cfg=pcfg, pretrained_path=a.policy_path,
        preprocessor_overrides={"device_processor": {"device": str(policy.config.device)},
                                "rename_observations_processor": {"rename_map": {}}},
    )  # fmt: skip
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=pcfg)
    t0 = time.time()
    successes, rewards = [], []
    for i in range(0, len(placements), a.batch_size):
        batch = placements[i : i + a.batch_size]
        fns = [
            (lambda pl=pl: gym.make(env_cfg.gym_id, disable_env_checker=True,
                                    **{**env_cfg.gym_kwargs, "placement": "fixed", "placements": [pl]}))
            for pl in batch
        ]  # fmt: skip
        vec = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        try:
            with torch.no_grad():
                info = eval_policy(vec, policy, env_pre, env_post, pre, post, n_episodes=len(batch),
                                   start_seed=a.seed + i)  # fmt: skip
        finally:
            vec.close()
        successes += [bool(e["success"]) for e in info["per_episode"]]
        rewards += [e["max_reward"] for e in info["per_episode"]]
        print(f"grid eval: {len(successes)}/{len(placements)} episodes, {sum(successes)} successes", flush=True)
    out = Path(a.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = max(1, len(successes))
    _write_json(out / "eval_info.json", {
        "per_task": [{"task_group": a.env_type, "task_id": 0,
                      "metrics": {"successes": successes, "max_rewards": rewards, "placements": placements}}],
        "overall": {"pc_success": 100.0 * sum(successes) / n, "n_episodes": len(successes),
                    "eval_s": time.time() - t0},
    })  # fmt: skip
    return 0
