"""Where a joint-space chunk starts from (lerobot_rnd/anchor.py). References: MuJoCo's simulated SO-101 (its sag
under gravity), the dataset's own action rows, and the action the policy itself returned."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lerobot_rnd import so101
from lerobot_rnd.action_adapters import ActionAdapter
from lerobot_rnd.anchor import anchor_state
from tests.helpers import gl_available, make_policy, training_batch


def _adapter(anchor: str) -> ActionAdapter:
    return ActionAdapter.from_dict({**so101.so101_action_adapter(), "anchor": anchor})


@pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")
def test_the_simulated_so101_sinks_when_sent_its_measured_joints_and_a_chunk_from_the_last_command_holds_it():
    from lerobot_rnd.sim.so101_env import RnDSO101Env

    env = RnDSO101Env(task="reach-target", observation_height=32, observation_width=32, terminate_on_success=False)
    env.reset(seed=100)
    q_command = env.joints().copy()
    z_start = env.ee_site_pos()[2]
    for _ in range(60):  # the same command: the servos hold the arm a little below it
        env.step(q_command.astype(np.float32))
    assert abs(env.ee_site_pos()[2] - z_start) < 0.01
    q_sagged = env.joints().copy()
    assert np.abs(q_sagged[:5] - q_command[:5]).max() > 0.3  # degrees of sag: the measured joints are not the command

    # A chunk that holds still (every step the last command), written from either anchor.
    state = torch.tensor(q_sagged, dtype=torch.float64)[None, None]  # (B=1, H=1, 6)
    chunk = torch.tensor(q_command, dtype=torch.float64).expand(1, 8, 6)
    for anchor, still in (("last_command", True), ("measured", False)):
        adapter = _adapter(anchor)
        anchored = anchor_state(adapter, state, chunk[:, 0], None)[:, -1]
        T_base_ee = adapter.forward_kinematics(adapter.to_urdf_units(adapter.joints_from_state(anchored)))
        T_ee_target, _ = adapter.to_rnd(chunk, T_base_ee, state=anchored)
        moves = T_ee_target[..., :3, 3].norm(dim=-1).max().item()
        assert (moves < 1e-6) if still else (moves > 1e-3), (anchor, moves)

    env.reset(seed=100)
    for _ in range(60):  # a "stay" re-anchored on the measured joints every step: the arm sinks to the table
        env.step(env.joints().astype(np.float32))
    assert z_start - env.ee_site_pos()[2] > 0.05


def test_anchor_state_puts_the_last_command_into_the_last_frames_joints_only():
    state = torch.arange(2 * 2 * 6, dtype=torch.float32).reshape(2, 2, 6)
    previous = torch.full((2, 6), -7.0)
    out = anchor_state(_adapter("last_command"), state, previous, torch.tensor([True, False]))
    expected = state.clone()
    expected[0, -1, :5] = -7.0  # five body joints; the gripper stays measured; sample 1 has no previous action
    torch.testing.assert_close(out, expected)
    assert anchor_state(_adapter("measured"), state, previous, None) is state
    assert anchor_state(_adapter("last_command"), state, None, None) is state
    with pytest.raises(ValueError, match="anchor"):
        ActionAdapter.from_dict({**so101.so101_action_adapter(), "anchor": "leader"})


@pytest.fixture(scope="module")
def toy_so101_root(tmp_path_factory):
    from lerobot_rnd.testing import record_toy_so101_dataset

    return record_toy_so101_dataset(tmp_path_factory.mktemp("toy_so101_anchor") / "toy_so101")


def test_training_starts_from_the_datasets_previous_action_and_inference_from_the_last_action_sent(
    toy_so101_root, monkeypatch
):
    policy, _ = make_policy(toy_so101_root)
    cfg = policy.config
    assert policy.model.action_adapter.anchor == "last_command"  # the SO-101 preset's
    batch = training_batch(toy_so101_root, cfg, n=4)
    assert batch["action"].shape[1] == cfg.chunk_size + 1 and bool(batch["action_is_pad"][0, 0])  # frame 0: none
    batch["action"][:, 0, :5] += 3.0  # the toy arm tracks its commands exactly; make the command stand out
    seen = {}

    def spy_loss(images, state, action, action_is_pad, task_index=None):
        seen.update(state=state, action=action, pad=action_is_pad)
        return action.sum() * 0, {}

    monkeypatch.setattr(policy.model, "compute_loss", spy_loss)
    policy.forward(batch)
    measured = batch["observation.state"]
    expected = torch.where(batch["action_is_pad"][:, :1], measured[:, -1, :5], batch["action"][:, 0, :5])
    torch.testing.assert_close(seen["state"][:, -1, :5], expected)
    torch.testing.assert_close(seen["state"][:, :-1], measured[:, :-1])
    torch.testing.assert_close(seen["state"][:, -1, 5], measured[:, -1, 5])
    torch.testing.assert_close(seen["action"], batch["action"][:, 1:])
    assert torch.equal(seen["pad"], batch["action_is_pad"][:, 1:])

    states = []

    def spy_generate(images, state, noise=None, task_index=None):
        states.append(state.clone())
        return torch.randn(state.shape[0], cfg.chunk_size, 6)

    monkeypatch.setattr(policy.model, "generate_actions", spy_generate)
    policy.reset()
    obs = {k: v[:, -1] for k, v in batch.items() if k.startswith("observation.")}
    sent = [policy.select_action(obs) for _ in range(cfg.n_action_steps + 1)]
    assert len(states) == 2
    torch.testing.assert_close(states[0][:, -1], obs["observation.state"])  # nothing sent yet: the measured joints
    torch.testing.assert_close(states[1][:, -1, :5], sent[cfg.n_action_steps - 1][:, :5])
    policy.reset()
    policy.select_action(obs)
    torch.testing.assert_close(states[2][:, -1], obs["observation.state"])  # a new episode forgets the last one


def test_statistics_windows_are_anchored_on_the_previous_row_of_the_same_episode():
    from lerobot_rnd.statistics import iter_all_windows

    ac = [np.arange(5 * 6, dtype=np.float32).reshape(5, 6) + 100 * e for e in range(2)]
    episodes = [(a - 0.5, a) for a in ac]
    calls = []

    def anchor(state, previous, has_previous):
        calls.append((previous, has_previous))
        return state

    list(iter_all_windows(episodes, n_obs_steps=2, horizon=3, anchor=anchor))
    previous, has_previous = calls[0]
    assert has_previous.tolist() == [False, True, True, True, True] * 2
    expected = np.concatenate([np.concatenate([a[:1], a[:-1]]) for a in ac])  # row i-1; row 0 where none
    np.testing.assert_array_equal(previous.numpy(), expected)
