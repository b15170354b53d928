"""Normalisation statistics of R&D's targets, estimated from a LeRobot dataset on disk.

R&D normalises its targets to [-1, 1] by min/max (the paper's appendix: without it nothing is learnt):
the diffused action chunk (jointly over the horizon: the 6-D translation + rotation vector of `T_ee_target`, or
the joint targets with `diffusion_space="joints"`) and the per-pixel image-space displacement (per camera and axis).
"""

import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from lerobot.utils.constants import ACTION, OBS_STATE

logger = logging.getLogger(__name__)

MIN_RANGE = 1e-4


class MinMaxStats(nn.Module):
    """Min/max normaliser to [-1, 1] whose statistics are buffers (saved in model.safetensors).

    `shape` is the shape of min and max; they broadcast against the trailing dims of the data.
    Before `set` is called the normaliser is the identity (min -1, max +1).
    """

    def __init__(self, shape: tuple[int, ...]):
        super().__init__()
        self.register_buffer("min", -torch.ones(shape))
        self.register_buffer("max", torch.ones(shape))

    def set(self, minimum: Tensor, maximum: Tensor) -> None:
        """Store statistics; a range below MIN_RANGE is widened symmetrically so values stay finite."""
        minimum = torch.as_tensor(minimum, dtype=torch.float32).reshape(self.min.shape)
        maximum = torch.as_tensor(maximum, dtype=torch.float32).reshape(self.max.shape)
        if not (torch.isfinite(minimum).all() and torch.isfinite(maximum).all()):
            raise ValueError("Normalisation statistics contain NaN or inf: check the dataset.")
        centre = (minimum + maximum) / 2
        half = ((maximum - minimum) / 2).clamp_min(MIN_RANGE / 2)
        self.min.copy_(centre - half)
        self.max.copy_(centre + half)

    def normalize(self, x: Tensor) -> Tensor:
        return 2 * (x - self.min) / (self.max - self.min) - 1

    def unnormalize(self, x: Tensor) -> Tensor:
        return (x + 1) / 2 * (self.max - self.min) + self.min


def load_episode_arrays(dataset_root: str | Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Read (state (N, D), action (N, A)) per episode from a LeRobot v3 dataset's parquet files."""
    import pandas as pd

    files = sorted(Path(dataset_root, "data").glob("**/*.parquet"))
    if not files:
        raise FileNotFoundError(f"No parquet data under {Path(dataset_root, 'data')}: is this a LeRobot dataset?")
    frame = pd.concat([pd.read_parquet(f, columns=["episode_index", "frame_index", OBS_STATE, ACTION]) for f in files])
    frame = frame.sort_values(["episode_index", "frame_index"])
    episodes = []
    for _, ep in frame.groupby("episode_index", sort=True):
        episodes.append(
            (np.stack(ep[OBS_STATE].to_numpy()).astype(np.float32), np.stack(ep[ACTION].to_numpy()).astype(np.float32))
        )
    return episodes


def sample_training_windows(
    episodes: list[tuple[np.ndarray, np.ndarray]], n_obs_steps: int, horizon: int, num_samples: int, seed: int = 0,
    anchor: Callable | None = None,
) -> tuple[Tensor, Tensor, Tensor]:
    """Draw windows like LeRobot's sampler does (indices clamped at episode ends, padded steps flagged).

    Returns state (S, H, D), action (S, T, A), action_is_pad (S, T). `anchor(state, previous_action (S, A),
    has_previous (S,)) -> state`: where the chunk starts from (`lerobot_rnd.anchor.anchor_state`), if given.
    """
    rng = np.random.default_rng(seed)
    lengths = np.array([len(s) for s, _ in episodes])
    ep_ids = rng.choice(len(episodes), size=num_samples, p=lengths / lengths.sum())
    frame_ids = [int(rng.integers(0, lengths[e])) for e in ep_ids]
    return _windows(episodes, list(zip(ep_ids, frame_ids)), n_obs_steps, horizon, anchor)


def _windows(episodes, picks, n_obs_steps: int, horizon: int, anchor=None) -> tuple[Tensor, Tensor, Tensor]:
    """The training windows (state (S, H, D), action (S, T, A), action_is_pad (S, T)) at (episode, frame) picks."""
    states, actions, pads, previous = [], [], [], []
    for e, i in picks:
        st, ac = episodes[e]
        n = len(st)
        obs_idx = np.clip(np.arange(i - n_obs_steps + 1, i + 1), 0, n - 1)
        act_idx = np.arange(i, i + horizon)
        pads.append(act_idx >= n)
        states.append(st[obs_idx])
        actions.append(ac[np.clip(act_idx, 0, n - 1)])
        previous.append(ac[max(i - 1, 0)])
    state = torch.from_numpy(np.stack(states))
    if anchor is not None:
        state = anchor(state, torch.from_numpy(np.stack(previous)), torch.tensor([i > 0 for _, i in picks]))
    return state, torch.from_numpy(np.stack(actions)), torch.from_numpy(np.stack(pads))


def iter_all_windows(episodes, n_obs_steps: int, horizon: int, batch_size: int = 4096, anchor=None):
    """Every training window of the dataset (one per frame), in batches: yields (state, action, action_is_pad)."""
    picks = [(e, i) for e, (st, _) in enumerate(episodes) for i in range(len(st))]
    for start in range(0, len(picks), batch_size):
        yield _windows(episodes, picks[start : start + batch_size], n_obs_steps, horizon, anchor)


def _check_finite_rows(episodes) -> None:
    for e, (st, ac) in enumerate(episodes):
        for name, arr in (("observation.state", st), ("action", ac)):
            bad = ~np.isfinite(arr)
            if bad.any():
                row = int(np.argwhere(bad.any(axis=1))[0, 0])
                raise ValueError(
                    f"The dataset's {name!r} contains NaN or inf (episode {e}, frame {row}, "
                    f"{int(bad.sum())} value(s) in that episode): R&D's statistics would be NaN. Fix or drop those "
                    "frames (e.g. --dataset.episodes=[...] without that episode)."
                )


#: The target min/max are widened by this fraction of their range on each side, so no training target is clamped.
STATS_MARGIN = 0.05


def widen(minimum: Tensor, maximum: Tensor, margin: float = STATS_MARGIN) -> tuple[Tensor, Tensor]:
    """Widen [min, max] by `margin` x range on each side."""
    pad = (maximum - minimum) * margin
    return minimum - pad, maximum + pad


@torch.no_grad()
def estimate_rnd_statistics(
    dataset_root: str | Path,
    *,
    n_obs_steps: int,
    chunk_size: int,
    num_samples: int,
    n_cameras: int,
    image_size: tuple[int, int],
    ee_pose: Callable[[Tensor], Tensor],
    gripper_state: Callable[[Tensor], Tensor],
    to_rnd: Callable[..., tuple[Tensor, Tensor]],
    diffusion_target: Callable[[Tensor, Tensor, Tensor], Tensor],
    noisy_sample_targets: Callable[..., dict],
    device: torch.device | str = "cpu",
    batch_size: int = 16,
    seed: int = 0,
    anchor: Callable | None = None,
) -> dict[str, Tensor]:
    """Action, displacement and gripper statistics of R&D's training targets, from the dataset on disk.

    The model's pieces come in as functions: `ee_pose(state (S, H, D)) -> T_world_ee (S, H, 4, 4)`,
    `gripper_state(state) -> (S, H)`, `to_rnd(action (S, T, A), T_world_ee_now (S, 4, 4), state=...) ->
    (T_ee_target (S, T, 4, 4), gripper (S, T))` (the action adapter), `diffusion_target(action, T_ee_target,
    state_now (S, D)) -> (S, T, D')` (the unnormalised diffused variable), and `noisy_sample_targets(images,
    T_world_ee, gripper, T_ee_target, x_target, state_now, generator=..., action_stats=...)`
    (`RnDModel.noisy_sample_targets`); `anchor` as in `sample_training_windows`.

    - Action min/max over EVERY training window of the dataset (streamed, padded steps excluded), widened by
      `STATS_MARGIN`, so no training target falls outside [-1, 1].
    - Gripper: the open/closed ratio of the targets (the BCE's positive-class weight, clamped to [0.1, 10]).
    - Displacement min/max per camera and axis from `num_samples` random windows, produced exactly as
      training produces its targets (noised in the action normalisation just estimated), widened by the same margin.

    Returns {"action_min", "action_max"} (D',), {"displacement_min", "displacement_max"} (C, 3, 1, 1) and
    "gripper_pos_weight" (a scalar tensor).
    """
    episodes = load_episode_arrays(dataset_root)
    if not episodes or sum(len(s) for s, _ in episodes) == 0:
        raise ValueError(f"The dataset at {dataset_root} has no frames: record or select some episodes.")
    _check_finite_rows(episodes)
    big = torch.finfo(torch.float32).max
    a_min = a_max = None
    n_closed = n_open = 0
    for state, action, is_pad in iter_all_windows(episodes, n_obs_steps, chunk_size, anchor=anchor):
        state, action, valid = state.to(device), action.to(device), (~is_pad).to(device)
        T_world_ee = ee_pose(state)
        T_ee_target, grip = to_rnd(action, T_world_ee[:, -1], state=state[:, -1])
        a = diffusion_target(action, T_ee_target, state[:, -1]).float()  # (S, T, D')
        if a_min is None:
            a_min = torch.full(a.shape[-1:], big, device=device)
            a_max = torch.full(a.shape[-1:], -big, device=device)
        a_min = torch.minimum(a_min, torch.where(valid[..., None], a, big).amin((0, 1)))
        a_max = torch.maximum(a_max, torch.where(valid[..., None], a, -big).amax((0, 1)))
        n_closed += int(((grip > 0) & valid).sum())
        n_open += int(((grip <= 0) & valid).sum())
    a_min, a_max = widen(a_min, a_max)
    action_stats = MinMaxStats(tuple(a_min.shape)).to(device)
    action_stats.set(a_min, a_max)
    pos_weight = 1.0 if n_closed == 0 or n_open == 0 else min(10.0, max(0.1, n_open / n_closed))

    state, action, is_pad = sample_training_windows(episodes, n_obs_steps, chunk_size, num_samples, seed, anchor)
    d_min = torch.full((n_cameras, 3), float("inf"), device=device)
    d_max = torch.full((n_cameras, 3), float("-inf"), device=device)
    generator = torch.Generator(device="cpu").manual_seed(seed)
    h, w = image_size
    desc = f"R&D image-space target statistics ({len(state)} samples; fewer: --policy.stats_num_samples)"
    for start in tqdm(range(0, len(state), batch_size), desc=desc, leave=False):
        sl = slice(start, start + batch_size)
        st, ac, valid = state[sl].to(device), action[sl].to(device), (~is_pad[sl]).to(device)
        b = st.shape[0]
        T_world_ee = ee_pose(st)
        T_ee_target, _ = to_rnd(ac, T_world_ee[:, -1], state=st[:, -1])
        x_target = diffusion_target(ac, T_ee_target, st[:, -1])
        blank = torch.zeros(b, n_obs_steps, n_cameras, 3, h, w, device=device)
        sample = noisy_sample_targets(
            blank, T_world_ee, gripper_state(st), T_ee_target, x_target, st[:, -1], generator=generator,
            action_stats=action_stats,
        )
        disp = sample["displacement"]  # (b, T, C, 3, N)
        m = (sample["target_mask"] & valid[:, :, None, None]).unsqueeze(3)  # (b, T, C, 1, N)
        per_cam = disp.permute(2, 3, 0, 1, 4).reshape(n_cameras, 3, -1)
        per_cam_mask = m.expand_as(disp).permute(2, 3, 0, 1, 4).reshape(n_cameras, 3, -1)
        d_min = torch.minimum(d_min, torch.where(per_cam_mask, per_cam, float("inf")).amin(-1))
        d_max = torch.maximum(d_max, torch.where(per_cam_mask, per_cam, float("-inf")).amax(-1))
    never_seen = ~torch.isfinite(d_min)
    if never_seen.any():
        logger.warning(
            "Some cameras never saw the rendered gripper while estimating statistics (camera index, axis: %s): "
            "check the calibration. Using +-5 cm for them.",
            never_seen.nonzero().tolist(),
        )
        d_min = torch.where(never_seen, torch.full_like(d_min, -0.05), d_min)
        d_max = torch.where(never_seen, torch.full_like(d_max, 0.05), d_max)
    d_min, d_max = widen(d_min, d_max)
    return {
        "action_min": a_min,
        "action_max": a_max,
        "displacement_min": d_min[..., None, None],
        "displacement_max": d_max[..., None, None],
        "gripper_pos_weight": torch.tensor(pos_weight),
    }
