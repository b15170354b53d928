#!/usr/bin/env python
"""Where does a policy's gripper go? Roll a checkpoint out and record the gripper's path against the goal.

A failed reach episode only says "not within 5 cm". This script runs lerobot-eval's own rollout loop
(`lerobot.scripts.lerobot_eval.rollout`, same env, processors and seeds as `lerobot-eval --seed=<first>`)
and records, per episode, the gripper centre (MetaWorld's `tcp_center`, the SO-101's EE site, the Panda's EE frame)
at every step, the goal (the SO-101's target or cube, the Panda task's object), the closest
and final distances, how far the gripper still moved over the last 50 steps, and the nearest demo goal of
the policy's training set. It tells apart a policy that heads for the goal and stops short, one that goes
to where a demonstration went, and one that wanders. `goal_response` sums it up: per axis, how far the
gripper has moved towards the goal at step 30 (slope over the episodes, 1 = all the way), next to the same
number for the demonstrations. Any LeRobot policy type loads (R&D, ACT, Diffusion Policy).

    python benchmarks/trace_rollouts.py --policy-path <run>/checkpoints/003000/pretrained_model \
        --data outputs/benchmark/data/mw_reach-v3_random_s0_n10 --out benchmarks/results/trace_<name>.json

Seeds default to the validation seeds 100-119; the benchmark's test seeds (1000-) are refused unless
`--allow-test-seeds`, so a diagnosis cannot be tuned on them. `--policy-arg FIELD=VALUE` changes a sampler
setting of the checkpoint's config (e.g. `num_inference_steps=1`; `FIELD.KEY=VALUE` one key of a dict field, e.g.
`action_adapter.ik_orientation_weight=0.1`). Every trace also splits each final miss into
the part along the recording's static camera's ray through the goal (depth as that camera sees it) and the part
across it (`static_camera_ray_error`); `--reanalyse` adds that split to a trace written before it existed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.eval_train_placements import training_placements  # noqa: E402


def recording_settings(data_root: Path) -> dict:
    """The settings a recording was made with (`meta/rnd_recording.json`)."""
    return json.loads((data_root / "meta" / "rnd_recording.json").read_text())["settings"]


def recording_suite(data_root: Path) -> str:
    """The suite a recording was made in ("metaworld", "so101", ...)."""
    from lerobot_rnd.sim.record import recorded_setting

    return recorded_setting(recording_settings(data_root), "suite")


def demo_goals(data_root: Path) -> np.ndarray:
    """(N, 3) goal positions (world frame, m) of a recording's demos in episode order: MetaWorld, the placement's
    last three numbers; SO-101 reach-target, the target (x, y, z); SO-101 pick-cube, the cube's centre; the Panda
    tasks, where the scripted expert's gripper first meets the object (``panda_experts.first_contact_point``: the
    cube's centre, push-block's push start behind the block, the button's top)."""
    placements = np.array(training_placements(data_root), dtype=np.float64)
    if recording_suite(data_root) == "so101" and recording_settings(data_root)["task"] == "pick-cube":
        from lerobot_rnd.sim.so101_scene import CUBE_HALF

        return np.concatenate([placements[:, :2], np.full((len(placements), 1), CUBE_HALF)], axis=1)
    if recording_suite(data_root) == "panda":
        from lerobot_rnd.sim.panda_experts import first_contact_point

        task = recording_settings(data_root)["task"]
        return np.stack([first_contact_point(task, p) for p in placements])
    return placements[:, -3:]


def demo_hand_positions(data_root: Path, states: np.ndarray) -> np.ndarray:
    """(S, 3) hand positions (world frame, m) from a recording's (S, D) states: MetaWorld's state starts with the
    hand position; the SO-101's state is joints, so the gripper frame comes from the URDF's forward kinematics."""
    if recording_suite(data_root) != "so101":
        return states[:, :3]
    import torch

    from lerobot_rnd import so101

    return so101.forward_kinematics(torch.as_tensor(states, dtype=torch.float64))[..., :3, 3].numpy()


def goal_response(starts: np.ndarray, later: np.ndarray, goals: np.ndarray) -> dict:
    """How strongly the gripper follows the goal: per axis, the least-squares slope (and correlation) of the
    displacement `later - starts` against the goal's offset `goals - starts`, over episodes; all (N, 3).
    1 = moved all the way to the goal on that axis, 0 = moved the same whatever the goal (a policy that
    ignores the goal and replays an average demonstration). An axis on which the goal's offset does not vary (e.g.
    push-block's height: every episode starts and pushes at the same heights) has no slope: None for both."""
    out = {}
    for k, axis in enumerate("xyz"):
        offset, moved = goals[:, k] - starts[:, k], later[:, k] - starts[:, k]
        if np.std(offset) < 1e-4:  # under 0.1 mm of spread: nothing to regress on
            out[axis] = {"slope": None, "correlation": None}
            continue
        slope = float(np.polyfit(offset, moved, 1)[0])
        out[axis] = {"slope": round(slope, 3), "correlation": round(float(np.corrcoef(offset, moved)[0, 1]), 3)}
    return out


def demo_goal_response(data_root: Path, goals_demo: np.ndarray, step: int) -> dict:
    """`goal_response` of the demonstrations themselves at frame `step` (the hand position, `demo_hand_positions`;
    the gripper centre moves with it)."""
    import pandas as pd

    frames = pd.concat([pd.read_parquet(f) for f in sorted((data_root / "data").glob("*/*.parquet"))])
    starts, later = [], []
    for _, ep in sorted(frames.groupby("episode_index"), key=lambda kv: kv[0]):
        ep = ep.sort_values("frame_index")
        hand = demo_hand_positions(data_root, np.stack(ep["observation.state"].to_numpy()))
        starts.append(hand[0])
        later.append(hand[min(step, len(hand) - 1)])
    return goal_response(np.array(starts), np.array(later), goals_demo)


def static_camera_ray_error(final: np.ndarray, goal: np.ndarray, cam_pos: np.ndarray) -> dict:
    """Split a final position's miss (metres, world frame) into the part along the static camera's ray through
    the goal (depth as that camera sees it; + = beyond the goal, away from the camera) and the part across it
    (what that camera shows as a wrong image position). final, goal, cam_pos: (3,)."""
    ray = (goal - cam_pos) / np.linalg.norm(goal - cam_pos)
    miss = final - goal
    along = float(miss @ ray)
    return {"along_ray": round(along, 4), "across_ray": round(float(np.linalg.norm(miss - along * ray)), 4)}


def static_camera_position(data_root: Path) -> tuple[str, np.ndarray] | None:
    """(camera key, (3,) position in the world) of the recording's first static camera (one with `T_world_cam`
    in `meta/rnd_embodiment.json`), or None if it has none."""
    path = data_root / "meta" / "rnd_embodiment.json"
    if not path.exists():
        return None
    for key, cam in json.loads(path.read_text())["cameras"].items():
        if "T_world_cam" in cam:
            return key, np.asarray(cam["T_world_cam"], dtype=np.float64)[:3, 3]
    return None


def ray_error_summary(episodes: list[dict], cam_pos: np.ndarray) -> dict:
    """Medians (metres) of `static_camera_ray_error` over the failed and the successful episodes."""
    out = {}
    for name, keep in (("failures", False), ("successes", True)):
        errs = [static_camera_ray_error(np.array(e["final_tcp"]), np.array(e["goal"]), cam_pos)
                for e in episodes if e["success"] == keep]  # fmt: skip
        out[name] = {"episodes": len(errs)} | ({
            "median_along_ray": round(float(np.median([r["along_ray"] for r in errs])), 4),
            "median_abs_along_ray": round(float(np.median([abs(r["along_ray"]) for r in errs])), 4),
            "median_across_ray": round(float(np.median([r["across_ray"] for r in errs])), 4),
        } if errs else {})  # fmt: skip
    return out


def _typed_value(pair: str, key: str, current, text: str):
    """`text` cast to the type of `current` (bool: true/false only); a ValueError names the pair."""
    if isinstance(current, bool):
        if text.lower() not in ("true", "false"):
            raise ValueError(f"--policy-arg {pair!r}: {key} is a bool; write true or false")
        return text.lower() == "true"
    if isinstance(current, (int, float, str)):
        try:
            return type(current)(text)
        except ValueError:
            raise ValueError(f"--policy-arg {pair!r}: {key} needs a {type(current).__name__}") from None
    raise ValueError(f"--policy-arg {pair!r}: {key} ({type(current).__name__}) cannot be set here")


def parse_policy_args(config, pairs: list[str]):
    """A copy of a loaded policy config with `KEY=VALUE` overrides, each cast to the type of the field's current
    value (bool accepts true/false only) and checked by the config's own validation (`dataclasses.replace`
    runs `__post_init__`). `FIELD.KEY=VALUE` sets one existing key of a dict field, e.g.
    `action_adapter.ik_orientation_weight=0.1` (an R&D checkpoint's IK weight, used only at inference). Unknown
    fields or keys and unparsable or invalid values raise ValueError naming them."""
    import copy
    import dataclasses

    overrides = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        name, dot, sub = key.partition(".")
        if not sep or not hasattr(config, name):
            raise ValueError(f"--policy-arg {pair!r}: expected FIELD=VALUE with a field of {type(config).__name__}")
        if dot:
            table = overrides.get(name, getattr(config, name))
            if not isinstance(table, dict) or sub not in table:
                known = sorted(table) if isinstance(table, dict) else []
                raise ValueError(f"--policy-arg {pair!r}: {name} has no key {sub!r}"
                                 + (f" (keys: {', '.join(known)})" if known else f" ({name} is not a dict)"))
            table = copy.deepcopy(table)
            table[sub] = _typed_value(pair, key, table[sub], text)
            overrides[name] = table
        else:
            overrides[key] = _typed_value(pair, key, getattr(config, key), text)
    return dataclasses.replace(config, **overrides) if overrides else config


def add_ray_split(result: dict, data_root: Path) -> dict:
    """Add the static-camera ray split (per episode and summed up) to a trace result, in place; a recording
    without a static camera leaves it as it was."""
    cam = static_camera_position(data_root)
    if cam is not None:
        for ep in result["episodes"]:
            ep["static_camera_ray_error"] = static_camera_ray_error(np.array(ep["final_tcp"]), np.array(ep["goal"]),
                                                                    cam[1])  # fmt: skip
        result["static_camera"] = cam[0]
        result["static_camera_ray_error"] = ray_error_summary(result["episodes"], cam[1])
    return result


def reanalyse(path: Path, data_root: Path) -> dict:
    """Add the static-camera ray split to a trace JSON written before it existed (the episodes' final positions
    and goals are already there); returns the updated result."""
    result = add_ray_split(json.loads(path.read_text()), data_root)
    path.write_text(json.dumps(result, indent=1))
    return result


def summarise(tcp: np.ndarray, goal: np.ndarray, goals_demo: np.ndarray, n_steps: int) -> dict:
    """tcp (S, 3) gripper centre after reset and after every step, goal (3,) -> one episode's record (metres).

    The entry after the episode's last step is dropped: the vector env resets an episode in the step that ends
    it, so that entry is already the next episode's start.
    """
    tcp = tcp[:n_steps]
    dist = np.linalg.norm(tcp - goal, axis=1)
    nearest = int(np.argmin(np.linalg.norm(goals_demo - goal, axis=1)))
    start_to_goal = goal - tcp[0]
    travelled = tcp[-1] - tcp[0]
    along = float(travelled @ start_to_goal / np.linalg.norm(start_to_goal) ** 2)  # 1 = reached the goal's depth
    return {
        "goal": goal.round(4).tolist(),
        "start_distance": round(float(dist[0]), 4),
        "min_distance": round(float(dist.min()), 4),
        "final_distance": round(float(dist[-1]), 4),
        "fraction_of_the_way": round(along, 3),
        "moved_last_50_steps": round(float(np.linalg.norm(tcp[-1] - tcp[max(0, len(tcp) - 51)])), 4),
        "nearest_demo": nearest,
        "goal_to_nearest_demo_goal": round(float(np.linalg.norm(goals_demo[nearest] - goal)), 4),
        "final_to_nearest_demo_goal": round(float(np.linalg.norm(goals_demo[nearest] - tcp[-1])), 4),
        "final_tcp": tcp[-1].round(4).tolist(),
        "tcp_every_10_steps": tcp[::10].round(4).tolist(),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--policy-path", help="a pretrained_model directory (required unless --reanalyse)")
    p.add_argument("--data", required=True, help="the training dataset root (its demo goals and cameras)")
    p.add_argument("--seed", type=int, default=100, help="first seed, as lerobot-eval --seed (default 100)")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--batch-size", type=int, default=10)
    p.add_argument("--allow-test-seeds", action="store_true")
    p.add_argument("--response-step", type=int, default=30, help="step (a multiple of 10) at which the gripper's "
                   "displacement is compared with the goal's offset, for the policy and its demos (default 30)")
    p.add_argument("--policy-arg", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a setting of the loaded config, e.g. num_inference_steps=1, or one key of a dict "
                   "field, e.g. action_adapter.ik_orientation_weight=0.1 (repeatable)")
    p.add_argument("--reanalyse", action="store_true", help="only add the static-camera ray split to the existing "
                   "--out JSON (no rollouts)")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    if a.reanalyse:
        r = reanalyse(Path(a.out), Path(a.data))
        print(json.dumps(r.get("static_camera_ray_error"), indent=1))
        return 0
    if a.policy_path is None:
        p.error("--policy-path is required (a pretrained_model directory)")
    if a.seed + a.episodes > 1000 and not a.allow_test_seeds:
        p.error(f"--seed {a.seed} with {a.episodes} episodes reaches the benchmark's test seeds (1000-); "
                "diagnose on validation seeds, or pass --allow-test-seeds")  # fmt: skip

    import torch
    from lerobot.envs.factory import make_env, make_env_pre_post_processors
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors
    from lerobot.scripts.lerobot_eval import rollout
    from lerobot.utils.random_utils import set_seed

    from lerobot_rnd.modeling_rnd import RnDPolicy
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig
    from lerobot_rnd.sim.record import recorded_env_overrides
    from lerobot_rnd.sim.so101_env import RnDSO101EnvConfig

    data = Path(a.data)
    settings = recording_settings(data)
    suite = recording_suite(data)
    if suite not in ("metaworld", "so101", "panda"):
        p.error(f"--data {data}: a {suite!r} recording; this script traces MetaWorld, SO-101 and Panda recordings")
    if suite == "panda":  # the goal: the object (cube, block, button); the hand: the EE frame (pinch site)
        from benchmarks.harness.scales import SUITES
        from lerobot_rnd.sim.panda_env import RnDPandaEnvConfig

        env_cfg = RnDPandaEnvConfig(task=settings["task"], **recorded_env_overrides(settings),
                                    episode_length=SUITES["panda"]["scales"]["cpu"]["episode_length"])  # fmt: skip
        goal_of = lambda e: e.object_pos().copy()
        hand_of = lambda e: e.ee_pose()[:3, 3].copy()
    elif suite == "so101":
        env_cfg = RnDSO101EnvConfig(task=settings["task"], **recorded_env_overrides(settings))
        # the goal: the target for reach-target, the cube for pick-cube; the hand: MuJoCo's EE site
        goal_of = (lambda e: e.target_pos()) if settings["task"] == "reach-target" else (lambda e: e.cube_pos())
        hand_of = lambda e: e.ee_site_pos()
    else:
        env_cfg = RnDMetaWorldEnvConfig(task=settings.get("task", "reach-v3"), **recorded_env_overrides(settings))
        goal_of = lambda e: e.raw_observation[-3:].copy()
        hand_of = lambda e: e.tcp_center.copy()
    goals_demo = demo_goals(data)
    # as lerobot-eval: seed the global RNGs, then build the env, then the policy (a diffusion policy's sampling
    # noise comes from torch's global generator, so the same seed draws the same noise)
    set_seed(a.seed)
    envs = make_env(env_cfg, n_envs=a.batch_size)
    from lerobot.configs.policies import PreTrainedConfig

    policy_type = json.loads((Path(a.policy_path) / "config.json").read_text())["type"]
    policy_cfg = PreTrainedConfig.from_pretrained(a.policy_path)
    try:
        policy_cfg = parse_policy_args(policy_cfg, a.policy_arg)
    except ValueError as e:
        p.error(str(e))
    policy_cls = RnDPolicy if policy_type == "rnd" else get_policy_class(policy_type)
    policy = policy_cls.from_pretrained(a.policy_path, config=policy_cfg)
    policy.eval()
    pre, post = make_pre_post_processors(policy.config, pretrained_path=a.policy_path)
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=policy.config)

    vec = next(iter(next(iter(envs.values())).values())) if isinstance(envs, dict) else envs
    episodes = []
    t0 = time.time()
    for start in range(a.seed, a.seed + a.episodes, a.batch_size):
        seeds = list(range(start, min(start + a.batch_size, a.seed + a.episodes)))
        tcp_steps: list[np.ndarray] = []

        goal_at_reset: list[np.ndarray] = []

        def record(env):  # after reset, then after every step (an env that is done may reset again later)
            if not goal_at_reset:
                goal_at_reset.append(np.stack([goal_of(e.unwrapped) for e in env.envs]))
            tcp_steps.append(np.stack([hand_of(e.unwrapped) for e in env.envs]))

        with torch.no_grad():
            out = rollout(vec, policy, env_pre, env_post, pre, post, seeds=seeds, render_callback=record)
        goals = goal_at_reset[0]
        tcp = np.stack(tcp_steps, axis=1)  # (B, S, 3)
        done = out["done"].numpy()
        success = out["success"].numpy().any(axis=1)
        for i, s in enumerate(seeds):
            n_steps = int(np.argmax(done[i])) + 1 if done[i].any() else done.shape[1]
            ep = {"seed": s, "success": bool(success[i]), **summarise(tcp[i], goals[i], goals_demo, n_steps)}
            episodes.append(ep)
            print(f"seed {s}: {'success' if ep['success'] else 'failure'}  final {ep['final_distance'] * 100:5.1f} cm"
                  f"  min {ep['min_distance'] * 100:5.1f} cm  way {ep['fraction_of_the_way']:.2f}"
                  f"  moved(last 50) {ep['moved_last_50_steps'] * 100:4.1f} cm"
                  f"  goal-demo {ep['goal_to_nearest_demo_goal'] * 100:4.1f} cm"
                  f"  final-demo {ep['final_to_nearest_demo_goal'] * 100:4.1f} cm", flush=True)  # fmt: skip
    vec.close()
    step = a.response_step
    starts = np.array([e["tcp_every_10_steps"][0] for e in episodes])
    later = np.array([e["tcp_every_10_steps"][min(step // 10, len(e["tcp_every_10_steps"]) - 1)] for e in episodes])
    goals = np.array([e["goal"] for e in episodes])
    result = {
        "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]) if argv is None else None,
        "policy_path": a.policy_path,
        "data": a.data,
        "demo_goals": goals_demo.round(4).tolist(),
        "policy_type": policy_type,
        "global_seed": a.seed,
        "successes": sum(e["success"] for e in episodes),
        "goal_response_step": step,
        "policy_args": a.policy_arg,
        "goal_response": goal_response(starts, later, goals),
        "demo_goal_response": demo_goal_response(data, goals_demo, step),
        "episodes": episodes,
        "seconds": round(time.time() - t0, 1),
    }
    add_ray_split(result, data)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    for name in ("goal_response", "demo_goal_response"):
        print(name, f"at step {step}:", "  ".join(
            f"{k} {v['slope']:.2f} (r {v['correlation']:.2f})" if v["slope"] is not None else f"{k} - (no spread)"
            for k, v in result[name].items()))  # fmt: skip
    print(f"{result['successes']}/{len(episodes)}; wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
