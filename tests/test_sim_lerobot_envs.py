"""The plugin's simulated suites as LeRobot environments (`--env.type=rnd_mw` / `rnd_panda`): features, LeRobot's
vector env, observation preprocessing and episode truncation, checked through LeRobot's own factory."""

import importlib.util

import numpy as np
import pytest

from tests.helpers import gl_available

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

SUITES = [
    # env type, task, episode length, camera keys, state dim, action dim, fps, module the suite needs
    ("rnd_mw", "reach-v3", 5, ("corner2", "behindGripper"), 8, 4, 80, "metaworld"),
    ("rnd_panda", "press-button", 3, ("front", "wrist"), 8, 7, 10, "gym_hil"),
]


@pytest.mark.parametrize(("env_type", "task", "length", "cameras", "state_dim", "action_dim", "fps", "needs"),
                         SUITES, ids=[s[0] for s in SUITES])  # fmt: skip
def test_lerobot_env_config_and_make_env(env_type, task, length, cameras, state_dim, action_dim, fps, needs):
    if importlib.util.find_spec(needs) is None:
        pytest.skip(f"{needs} is not installed")
    import gymnasium as gym
    from lerobot.envs.configs import EnvConfig
    from lerobot.envs.factory import make_env
    from lerobot.envs.utils import env_to_policy_features, preprocess_observation

    import lerobot_policy_rnd  # noqa: F401  (the plugin shim LeRobot imports: registers the env types)

    cfg = EnvConfig.get_choice_class(env_type)(task=task, episode_length=length)
    assert "metaworld" not in cfg.type and "libero" not in cfg.type  # LeRobot would route those to its own
    assert cfg.gym_id.endswith(f"/{task}") and cfg.fps == fps
    feats = env_to_policy_features(cfg)
    for cam in cameras:
        assert feats[f"observation.images.{cam}"].shape == (3, 128, 128)
    assert feats["observation.state"].shape == (state_dim,) and feats["action"].shape == (action_dim,)
    vec = make_env(cfg, n_envs=2)[env_type][0]
    assert isinstance(vec, gym.vector.VectorEnv)
    obs, _ = vec.reset(seed=[0, 1])
    batch = preprocess_observation(obs)
    assert batch[f"observation.images.{cameras[0]}"].shape == (2, 3, 128, 128)
    assert batch["observation.state"].shape == (2, state_dim)
    done = np.zeros(2, bool)
    for _ in range(length):
        obs, _, term, trunc, info = vec.step(np.zeros((2, action_dim), np.float32))
        done |= term | trunc
    assert done.all()
    vec.close()
