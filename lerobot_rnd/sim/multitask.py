"""Several tasks in one run: ``--env.task=a,b,c`` for ``--env.type=rnd_mw`` / ``rnd_panda``.

LeRobot 0.4.4's ``make_env`` returns ``{suite: {task_id: vector env}}``. It builds one vector env per task only for
its own MetaWorld and LIBERO types; any other type gets one gym id, ``{cfg.type: {0: env}}``. For our env types with
a comma-separated task list, :func:`install_multitask_make_env` makes ``make_env`` return one vector env per task,
``{task: {0: env}}``, the layout LeRobot's own MetaWorld env gives ``--env.task=a,b,c``. ``lerobot-eval`` then
evaluates every task (``--eval.n_episodes`` each, from the same ``--seed``) and writes per-task, per-group and
overall success to ``eval_info.json`` as usual. Every other env type and every one-task call goes to LeRobot's own
``make_env`` unchanged.

Each env exposes ``task_description`` (the string its recorder writes into a dataset's frames), which
``lerobot-eval`` passes to the policy as ``observation["task"]``: a task-conditioned R&D policy reads it there.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable

#: modules that bind LeRobot's ``make_env`` at import time (``from lerobot.envs.factory import make_env``)
MAKE_ENV_MODULES = ("lerobot.envs.factory", "lerobot.scripts.lerobot_eval", "lerobot.scripts.lerobot_train")


def task_list(task: str | None) -> list[str]:
    """``"a, b,c"`` -> ``["a", "b", "c"]`` (an env config's or recorder's ``task``; empty entries dropped)."""
    return [t.strip() for t in str(task or "").split(",") if t.strip()]


def check_task_list(tasks: list[str], known: tuple[str, ...] | list[str], flag: str) -> None:
    """Raise a ValueError naming ``flag`` when ``tasks`` is empty, repeats a task or names an unknown one."""
    if not tasks:
        raise ValueError(f"{flag} is empty: name at least one task")
    repeated = sorted({t for t in tasks if tasks.count(t) > 1})
    if repeated:
        raise ValueError(f"{flag} names {', '.join(repeated)} more than once: list each task once")
    unknown = [t for t in tasks if t not in known]
    if unknown:
        raise ValueError(f"{flag}: unknown task(s) {', '.join(unknown)}; tasks: {', '.join(known)}")


def is_multitask_config(cfg) -> bool:
    """Whether ``cfg`` is one of our env configs (``rnd_mw`` / ``rnd_panda``) naming several tasks."""
    from lerobot_rnd.sim.mujoco_env import RnDSimEnvConfig

    return isinstance(cfg, RnDSimEnvConfig) and len(task_list(cfg.task)) > 1


def make_multitask_envs(cfg, n_envs: int = 1, use_async_envs: bool = False) -> dict[str, dict[int, object]]:
    """One vector env of ``n_envs`` copies per task of ``cfg.task`` (comma-separated): ``{task: {0: env}}``."""
    import gymnasium as gym
    from gymnasium.envs.registration import registry

    if n_envs < 1:
        raise ValueError("`n_envs` must be at least 1")
    tasks = task_list(cfg.task)
    known = sorted(k.split("/", 1)[1] for k in registry if k.startswith(f"{cfg.gym_namespace}/"))
    check_task_list(tasks, known, f"--env.type={cfg.type} --env.task")
    if getattr(cfg, "placements", None):
        raise ValueError(
            f"--env.placements lists placements of one task, but --env.task names {len(tasks)}: evaluate the tasks "
            "one at a time with fixed placements, or drop --env.placements"
        )
    env_cls = gym.vector.AsyncVectorEnv if use_async_envs else gym.vector.SyncVectorEnv
    kwargs = dict(cfg.gym_kwargs)
    out = {}
    for task in tasks:
        factory = functools.partial(
            gym.make, f"{cfg.gym_namespace}/{task}", disable_env_checker=cfg.disable_env_checker, **kwargs
        )
        out[task] = {0: env_cls([factory] * n_envs, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)}
    return out


def multitask_make_env(make_env: Callable) -> Callable:
    """``make_env`` that builds one vector env per task for our multi-task configs, else calls ``make_env``."""
    if getattr(make_env, "_rnd_multitask", False):
        return make_env

    @functools.wraps(make_env)
    def wrapped(cfg, n_envs: int = 1, use_async_envs: bool = False, *args, **kwargs):
        if is_multitask_config(cfg):
            return make_multitask_envs(cfg, n_envs=n_envs, use_async_envs=use_async_envs)
        return make_env(cfg, n_envs, use_async_envs, *args, **kwargs)

    wrapped._rnd_multitask = True
    return wrapped


def install_multitask_make_env() -> None:
    """Route LeRobot's ``make_env`` through :func:`multitask_make_env` in every module that has imported it (the
    factory, ``lerobot-eval``, ``lerobot-train``); idempotent. Other env types are not affected."""
    import lerobot.envs.factory  # noqa: F401  (so that the factory is patched before anyone imports it)

    for name in MAKE_ENV_MODULES:
        module = sys.modules.get(name)
        if module is not None and callable(getattr(module, "make_env", None)):
            module.make_env = multitask_make_env(module.make_env)
