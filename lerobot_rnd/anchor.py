"""Where an action chunk starts from: the arm's measured joints, or the joint targets it was last sent.

R&D writes a chunk relative to the current end-effector pose (`T_ee_target`, `action_adapters`). A joint-space
arm with position servos does not reach its targets under gravity: the measured joints sit a little below the
last command (the servo's steady-state error). A chunk that starts from the measured joints and says "stay"
then commands the sagged pose, the arm sags again below it, and so on: it sinks step by step. On the simulated
SO-101, commanding the measured joints at every step takes the gripper from 12 cm above the table to the table
in 60 steps (`tests/test_anchor.py`). The demos hold their pose only because their targets sit that small sag
above the state, an offset the policy must then reproduce exactly.

With `JointPositionAdapter(anchor="last_command")` the chunk starts from the previous action instead, so "stay"
is the identity and the sag never enters the chunk. The policy puts those joints into the state's last frame
before anything reads it (the EE pose, the rendered gripper, the chunk's targets, the IK's seed): in training
the dataset's action one step before the chunk (`RnDConfig.action_delta_indices` starts at -1), at inference
the last action the policy sent. Where there is none (an episode's first frame), the measured joints stand in.
"""

from __future__ import annotations

import torch
from torch import Tensor

from lerobot_rnd.action_adapters import ActionAdapter


def anchors_on_last_command(adapter: ActionAdapter) -> bool:
    """Whether `adapter` starts its chunks from the last command (a joint-position adapter with that anchor)."""
    return getattr(adapter, "anchor", "measured") == "last_command"


def anchor_state(
    adapter: ActionAdapter, state: Tensor, previous_action: Tensor | None, has_previous: Tensor | None
) -> Tensor:
    """The state history (B, H, S) with the last frame's joints replaced by `previous_action` (B, A)'s joint
    targets where `has_previous` (B,) is True (None: everywhere), if the adapter anchors on the last command;
    otherwise `state` unchanged. The action's first n columns are the n joints (`JointPositionAdapter`); they go
    to the state's `state_joint_indices` (default its first n entries)."""
    if previous_action is None or not anchors_on_last_command(adapter):
        return state
    n = adapter.n_joints
    idx = adapter.state_joint_indices if adapter.state_joint_indices is not None else list(range(n))
    idx = torch.as_tensor(idx, device=state.device)
    now = state[:, -1]
    commanded = now.index_copy(-1, idx, previous_action[..., :n].to(now.dtype))
    if has_previous is not None:
        commanded = torch.where(has_previous[:, None].to(torch.bool), commanded, now)
    return torch.cat([state[:, :-1], commanded[:, None]], dim=1)
