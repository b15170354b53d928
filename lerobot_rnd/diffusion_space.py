"""What R&D diffuses: the normalised variable `a` (B, T, D) of an action chunk, and the gripper poses it stands for.

The sampler and the training loss never look inside `a`; they ask its space two questions:
`to_pose(a) -> T_ee_target` (where to draw the gripper: the rigid transform from the current end-effector frame
to each future step's, (B, T, 4, 4)) and `from_pose(T_ee_target) -> a` (the variable of a pose that the
image-space registration produced). Two spaces, chosen by `RnDConfig.diffusion_space`:

- `EEPoseSpace` ("ee_pose", the paper's): a = [translation, rotation vector] of `T_ee_target`, D = 6.
- `JointSpace` ("joints"): a = the dataset's joint targets q (absolute, in its units), D = the arm's joints.
  The gripper is drawn at FK(q), so every candidate the network sees is a pose the arm can reach; the
  registration's rigid update comes back through inverse kinematics seeded at the current joints. Meant for
  arms with fewer than 6 joints (the SO-101's 5), whose rigid updates are mostly unreachable.

Both normalise with the model's `MinMaxStats` (D,), estimated from the dataset.
"""

from torch import Tensor

from lerobot_rnd.action_adapters import ActionAdapter, JointPositionAdapter
from lerobot_rnd.configuration_rnd import DIFFUSION_SPACES
from lerobot_rnd.geometry import action_from_pose, invert_transform, pose_from_action


def diffusion_dim(diffusion_space: str, adapter: ActionAdapter) -> int:
    """D, the size of one step of the diffused variable, for this space and action adapter."""
    return adapter.n_joints if diffusion_space == "joints" else 6


def check_diffusion_space(diffusion_space: str, adapter: ActionAdapter) -> None:
    """Raise a ValueError naming the fix where `diffusion_space` does not fit the dataset's actions."""
    if diffusion_space not in DIFFUSION_SPACES:
        raise ValueError(f"`diffusion_space` must be one of {DIFFUSION_SPACES}. Got {diffusion_space!r}.")
    if diffusion_space == "joints" and not isinstance(adapter, JointPositionAdapter):
        raise ValueError(
            f"`diffusion_space` 'joints' diffuses the dataset's joint targets, so it needs the joint_positions "
            f"action adapter; this embodiment's is {adapter.name!r}. Use --policy.diffusion_space=ee_pose, or an "
            "embodiment whose actions are joint positions (e.g. --policy.embodiment=so101)."
        )


class DiffusionSpace:
    """What both spaces share: the min/max normalisation `stats` (a `MinMaxStats` of shape (D,))."""

    def __init__(self, stats):
        self.stats = stats

    def normalize(self, x: Tensor) -> Tensor:
        """The unnormalised variable (B, T, D) -> a."""
        return self.stats.normalize(x)


class EEPoseSpace(DiffusionSpace):
    """a (B, T, 6) = normalised [translation (m), rotation vector (rad)] of T_ee_target (the paper's action)."""

    @staticmethod
    def target(action: Tensor, T_ee_target: Tensor) -> Tensor:
        """The unnormalised variable (B, T, 6) of a ground-truth chunk (its poses T_ee_target (B, T, 4, 4))."""
        return action_from_pose(T_ee_target)

    def to_pose(self, a: Tensor) -> Tensor:
        """a (B, T, 6) normalised -> T_ee_target (B, T, 4, 4)."""
        return pose_from_action(self.stats.unnormalize(a))

    def from_pose(self, T_ee_target: Tensor) -> Tensor:
        """T_ee_target (B, T, 4, 4) -> a (B, T, 6) normalised (not clamped)."""
        return self.stats.normalize(action_from_pose(T_ee_target))

    def dataset_action(self, a: Tensor, gripper: Tensor, adapter: ActionAdapter, T_world_ee_now: Tensor,
                       state_now: Tensor) -> Tensor:
        """a (B, T, 6), R&D gripper (B, T) -> the dataset's action chunk (B, T, A), through the action adapter."""
        return adapter.from_rnd(self.to_pose(a), gripper, T_world_ee_now, state=state_now)


class JointSpace(DiffusionSpace):
    """a (B, T, n) = normalised joint targets q in the dataset's units (absolute, as the dataset's action).

    adapter: the `JointPositionAdapter` (URDF chain, unit scale, IK); state_now (B, S): the current robot state,
    whose joints q_now (B, n) anchor the poses: T_ee_target = FK(q_now)^-1 FK(q), both in the base frame.
    """

    def __init__(self, stats, adapter: JointPositionAdapter, state_now: Tensor):
        super().__init__(stats)
        self.adapter = adapter
        self.q_now = adapter.joints_from_state(state_now.float())  # (B, n), dataset units
        self.T_base_ee_now = adapter.forward_kinematics(adapter.to_urdf_units(self.q_now))  # (B, 4, 4)

    def target(self, action: Tensor, T_ee_target: Tensor) -> Tensor:
        """The unnormalised variable (B, T, n) of a ground-truth chunk: the dataset action's joint columns."""
        return action[..., : self.adapter.n_joints].float()

    def to_joints(self, a: Tensor) -> Tensor:
        """a (B, T, n) normalised -> joint targets (B, T, n) in the dataset's units."""
        return self.stats.unnormalize(a)

    def to_pose(self, a: Tensor) -> Tensor:
        """a (B, T, n) normalised -> T_ee_target (B, T, 4, 4) = FK(q_now)^-1 FK(q)."""
        T_base_target = self.adapter.forward_kinematics(self.adapter.to_urdf_units(self.to_joints(a)))
        return (invert_transform(self.T_base_ee_now)[:, None] @ T_base_target.to(self.T_base_ee_now)).to(a.dtype)

    def from_pose(self, T_ee_target: Tensor) -> Tensor:
        """T_ee_target (B, T, 4, 4) -> a (B, T, n) normalised, by IK seeded at the current joints (not clamped)."""
        T_base_target = self.T_base_ee_now[:, None].to(T_ee_target) @ T_ee_target
        q_now = self.adapter.to_urdf_units(self.q_now).to(T_ee_target)
        q, _ = self.adapter.inverse_kinematics(T_base_target, q_now[:, None])
        return self.stats.normalize(self.adapter.from_urdf_units(q).to(T_ee_target.dtype))

    def dataset_action(self, a: Tensor, gripper: Tensor, adapter: ActionAdapter, T_world_ee_now: Tensor,
                       state_now: Tensor) -> Tensor:
        """a (B, T, n), R&D gripper (B, T) -> the dataset's action chunk (B, T, A): the joint targets are the action
        as they are (no IK)."""
        return adapter.compose_action(self.to_joints(a), gripper)
