"""Checkpoints and training behaviour recorded before the issue-10 refactor are kept.

References: tests/fixtures/, recorded once by tests/fixtures/make_backward_compat_fixtures.py: a checkpoint saved
at commit aa39157 (the oldest format: before the method fixes and the module split) with the actions it
predicted for fixed inputs, and the first 20 training losses at fixed seeds recorded at commit 0565893 (after
the method fixes, before the module split).
"""

import json

import pytest
import torch
from safetensors.torch import load_file

from tests.helpers import (
    FIXTURE_CHECKPOINT,
    FIXTURE_EXPECTED_ACTIONS,
    FIXTURE_TRAINING_LOSSES,
    LOSS_STEPS,
    record_training_losses,
)


def test_checkpoint_saved_before_the_refactor_loads_and_predicts_the_same_actions():
    from lerobot_rnd.modeling_rnd import RnDPolicy

    # Its config names its dataset's embodiment file, which is not here: the checkpoint alone must suffice.
    policy = RnDPolicy.from_pretrained(FIXTURE_CHECKPOINT)
    recorded = load_file(FIXTURE_EXPECTED_ACTIONS)
    expected, noise = recorded.pop("actions"), recorded.pop("noise")
    actions = policy.predict_action_chunk(recorded, noise=noise)
    assert actions.shape == expected.shape == (2, 4, 4)
    torch.testing.assert_close(actions, expected, rtol=1e-4, atol=1e-5)


def test_checkpoint_saved_before_history_rgb_overlay_existed_loads_with_overlay_on():
    """The fixture checkpoint's config.json has no `history_rgb_overlay` key (it was trained with the overlay,
    the only behaviour then); the new default is off, so loading must restore it, and only where absent."""
    from lerobot_rnd.configuration_rnd import RnDConfig, migrate_saved_config
    from lerobot_rnd.modeling_rnd import RnDPolicy

    saved = json.loads((FIXTURE_CHECKPOINT / "config.json").read_text())
    assert "history_rgb_overlay" not in saved
    assert RnDPolicy.from_pretrained(FIXTURE_CHECKPOINT).config.history_rgb_overlay is True

    cfg = RnDConfig()
    assert cfg.history_rgb_overlay is False
    assert migrate_saved_config(cfg, {"history_rgb_overlay": False}) == []
    assert cfg.history_rgb_overlay is False
    assert migrate_saved_config(cfg, {}) == ["history_rgb_overlay"]
    assert cfg.history_rgb_overlay is True


def test_old_checkpoint_without_the_migration_predicts_different_actions():
    """Guards the migration test above: with the new default the fixture's actions differ."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.pretrained import PreTrainedPolicy

    from lerobot_rnd.modeling_rnd import RnDPolicy

    config = PreTrainedConfig.from_pretrained(FIXTURE_CHECKPOINT)
    assert config.history_rgb_overlay is False
    policy = PreTrainedPolicy.from_pretrained.__func__(RnDPolicy, FIXTURE_CHECKPOINT, config=config)
    recorded = load_file(FIXTURE_EXPECTED_ACTIONS)
    expected, noise = recorded.pop("actions"), recorded.pop("noise")
    actions = policy.predict_action_chunk(recorded, noise=noise)
    assert (actions - expected).abs().max() > 1e-3


def test_first_training_losses_match_the_recorded_ones(toy_dataset_root):
    recorded = json.loads(FIXTURE_TRAINING_LOSSES.read_text())["steps"]
    losses = record_training_losses(toy_dataset_root, LOSS_STEPS)
    assert len(losses) == len(recorded) == LOSS_STEPS
    for step, (got, want) in enumerate(zip(losses, recorded, strict=True)):
        assert set(got) == set(want), step
        for key in want:
            assert got[key] == pytest.approx(want[key], rel=1e-4, abs=1e-6), (step, key)
