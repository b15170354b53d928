"""The ready configs in policies_config/ parse as lerobot-train configs and build valid policy configs."""

from pathlib import Path

import draccus
import pytest

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "policies_config").glob("**/*.json"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_config_parses_as_a_train_config(path):
    import lerobot.policies  # noqa: F401  (registers ACT and Diffusion Policy)
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_rnd  # noqa: F401  (registers rnd)
    import lerobot_rnd.sim  # noqa: F401  (registers rnd_mw; the core does not import the simulators)

    cfg = draccus.parse(TrainPipelineConfig, str(path), args=[])
    assert cfg.policy is not None and cfg.policy.type in {"rnd", "act", "diffusion"}
    assert cfg.env is not None and cfg.env.type == "rnd_mw"
    assert cfg.policy.push_to_hub is False
    if cfg.policy.type == "rnd":
        assert cfg.policy.n_obs_steps == 2 and cfg.policy.chunk_size == 8
    if cfg.policy.type == "act":
        assert cfg.policy.pretrained_backbone_weights is None  # no downloads offline
