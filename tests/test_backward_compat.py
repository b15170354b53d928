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


def _saved_with(tmp_path, **changes):
    """A copy of the fixture checkpoint whose config.json has `changes` applied."""
    import shutil

    ckpt = tmp_path / "ckpt"
    shutil.copytree(FIXTURE_CHECKPOINT, ckpt)
    config = json.loads((ckpt / "config.json").read_text())
    config.update(changes)
    (ckpt / "config.json").write_text(json.dumps(config, indent=4))
    return ckpt


def test_the_fixture_config_holds_retired_switches_at_the_behaviour_every_policy_now_has():
    """The fixture was saved when the config still had the retired switches (issue 32): it must name some, or the
    tests below do not test loading them."""
    from lerobot_rnd.configuration_rnd import RETIRED_FIELDS, RnDConfig

    saved = json.loads((FIXTURE_CHECKPOINT / "config.json").read_text())
    retired = set(saved) & set(RETIRED_FIELDS)
    assert {"point_map_scale", "texture_colors", "min_visible_points", "beta_schedule"} <= retired
    assert not retired & set(RnDConfig.__dataclass_fields__)


@pytest.mark.parametrize(("field", "value"), [("use_ema", True), ("point_map_scale", 2.0), ("denoise_step", "refine"),
                                             ("point_update", "interpolate")])  # fmt: skip
def test_a_checkpoint_that_used_a_retired_switch_is_refused_naming_the_field_and_the_tag(tmp_path, field, value):
    """Where a retired switch would change the predictions, loading it as if it were the default would silently
    give another policy: LeRobot's loader (lerobot-eval --policy.path) and RnDPolicy refuse it instead."""
    from lerobot.configs.policies import PreTrainedConfig

    from lerobot_rnd.configuration_rnd import RETIRED_FIELDS_TAG
    from lerobot_rnd.modeling_rnd import RnDPolicy

    ckpt = _saved_with(tmp_path, **{field: value})
    for load in (PreTrainedConfig.from_pretrained, RnDPolicy.from_pretrained):
        with pytest.raises(Exception, match=rf"(?s){field}.*{RETIRED_FIELDS_TAG}"):
            load(ckpt)


def test_a_training_only_retired_switch_loads_and_predicts_the_same(tmp_path, caplog):
    from lerobot_rnd.modeling_rnd import RnDPolicy

    ckpt = _saved_with(tmp_path, image_shift_augment=6, camera_dropout=0.3, embedding_init_std=0.02)
    with caplog.at_level("INFO"):
        policy = RnDPolicy.from_pretrained(ckpt)
    assert "image_shift_augment" in caplog.text
    recorded = load_file(FIXTURE_EXPECTED_ACTIONS)
    expected, noise = recorded.pop("actions"), recorded.pop("noise")
    torch.testing.assert_close(policy.predict_action_chunk(recorded, noise=noise), expected, rtol=1e-4, atol=1e-5)


def test_a_resumed_train_config_with_retired_switches_parses(tmp_path):
    """`lerobot-train --config_path=.../train_config.json --resume=true` parses the policy section the same way."""
    import draccus
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_rnd.sim  # noqa: F401  (registers rnd_mw)

    policy = json.loads((FIXTURE_CHECKPOINT / "config.json").read_text())
    train = {"dataset": {"repo_id": "local/x", "root": str(tmp_path)}, "policy": policy, "steps": 3,
             "env": {"type": "rnd_mw", "task": "reach-v3"}}  # fmt: skip
    (tmp_path / "train_config.json").write_text(json.dumps(train))
    cfg = draccus.parse(TrainPipelineConfig, str(tmp_path / "train_config.json"), args=[])
    assert cfg.policy.type == "rnd" and cfg.policy.dim_model == 32
    policy["use_ema"] = True
    (tmp_path / "train_config.json").write_text(json.dumps(train))
    with pytest.raises(Exception, match="use_ema"):
        draccus.parse(TrainPipelineConfig, str(tmp_path / "train_config.json"), args=[])


def test_other_policies_decode_exactly_as_before(tmp_path):
    """The decoding hook only touches `rnd` configs: an ACT config with an unknown key is refused by draccus as
    without the plugin, and a valid one parses."""
    import draccus
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.act.configuration_act import ACTConfig

    ACTConfig(pretrained_backbone_weights=None).save_pretrained(tmp_path / "act")
    assert isinstance(PreTrainedConfig.from_pretrained(tmp_path / "act"), ACTConfig)
    saved = json.loads((tmp_path / "act" / "config.json").read_text())
    saved["point_map_scale"] = 1.0
    (tmp_path / "act" / "config.json").write_text(json.dumps(saved))
    with pytest.raises(draccus.utils.DecodingError, match="point_map_scale"):
        PreTrainedConfig.from_pretrained(tmp_path / "act")
