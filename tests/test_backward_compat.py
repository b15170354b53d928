"""Checkpoints and training behaviour recorded before the issue-10 refactor are kept.

References: tests/fixtures/, recorded once by tests/fixtures/make_backward_compat_fixtures.py with the code at
commit aa39157 (before the module split): a saved checkpoint with the actions it predicted for fixed inputs,
and the first 20 training losses at fixed seeds.
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


def test_first_training_losses_match_the_recorded_ones(toy_dataset_root):
    recorded = json.loads(FIXTURE_TRAINING_LOSSES.read_text())["steps"]
    losses = record_training_losses(toy_dataset_root, LOSS_STEPS)
    assert len(losses) == len(recorded) == LOSS_STEPS
    for step, (got, want) in enumerate(zip(losses, recorded, strict=True)):
        assert set(got) == set(want), step
        for key in want:
            assert got[key] == pytest.approx(want[key], rel=1e-4, abs=1e-6), (step, key)
