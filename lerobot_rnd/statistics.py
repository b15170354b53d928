"""Normalisation statistics of R&D's targets, estimated from a LeRobot dataset on disk.

R&D normalises its targets to [-1, 1] by min/max (the paper's appendix: without it nothing is learnt):
the 6-D action chunk (translation + rotation vector of `T_ee_target`, jointly over the horizon or per step)
and the per-pixel image-space displacement (per camera and axis).
"""

import logging
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_rnd.geometry import action_from_pose, invert_transform, pose_from_action
from lerobot_rnd.sampler import displacement_target

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
    episodes: list[tuple[np.ndarray, np.ndarray]], n_obs_steps: int, horizon: int, num_samples: int, seed: int = 0
) -> tuple[Tensor, Tensor, Tensor]:
    """Draw windows like LeRobot's sampler does (indices clamped at episode ends, padded steps flagged).

    Returns state (S, H, D), action (S, T, A), action_is_pad (S, T).
    """
    rng = np.random.default_rng(seed)
    lengths = np.array([len(s) for s, _ in episodes])
    ep_ids = rng.choice(len(episodes), size=num_samples, p=lengths / lengths.sum())
    states, actions, pads = [], [], []
    for e in ep_ids:
        st, ac = episodes[e]
        n = len(st)
        i = rng.integers(0, n)
        obs_idx = np.clip(np.arange(i - n_obs_steps + 1, i + 1), 0, n - 1)
        act_idx = np.arange(i, i + horizon)
        pads.append(act_idx >= n)
        states.append(st[obs_idx])
        actions.append(ac[np.clip(act_idx, 0, n - 1)])
    return torch.from_numpy(np.stack(states)), torch.from_numpy(np.stack(actions)), torch.from_numpy(np.stack(pads))


@torch.no_grad()
def estimate_rnd_statistics(model, dataset_meta, batch_size: int = 64) -> dict[str, Tensor]:
    """Estimate action, displacement and gripper statistics for `model` (an `RnDModel`) from the dataset.

    The displacement statistics are measured exactly as training produces targets: normalised ground-truth
    chunks, a random diffusion step, noise, clamping, rendering, F_gt = T(a_gt, a_noisy) P - P.
    """
    cfg = model.config
    episodes = load_episode_arrays(dataset_meta.root)
    state, action, is_pad = sample_training_windows(
        episodes, cfg.n_obs_steps, cfg.chunk_size, cfg.stats_num_samples, seed=cfg_seed(cfg)
    )
    device = model.action_stats.min.device
    state, action, is_pad = state.to(device), action.to(device), is_pad.to(device)
    T_world_ee = model.ee_reader.pose(state)  # (S, H, 4, 4)
    T_ee_target, _ = model.action_adapter.to_rnd(action, T_world_ee[:, -1], state=state[:, -1])
    a = action_from_pose(T_ee_target)  # (S, T, 6)
    valid = ~is_pad
    big = torch.finfo(a.dtype).max
    if cfg.per_horizon_action_normalization:
        a_min = torch.where(valid[..., None], a, big).amin(0)
        a_max = torch.where(valid[..., None], a, -big).amax(0)
        a_min = torch.where(a_min > a_max, torch.zeros_like(a_min), a_min)
        a_max = torch.maximum(a_max, a_min)
    else:
        flat, flat_valid = a.reshape(-1, 6), valid.reshape(-1)
        a_min = torch.where(flat_valid[:, None], flat, big).amin(0)
        a_max = torch.where(flat_valid[:, None], flat, -big).amax(0)
    model.action_stats.set(a_min, a_max)

    n_cam = len(model.camera_keys)
    d_min = torch.full((n_cam, 3), float("inf"), device=device)
    d_max = torch.full((n_cam, 3), float("-inf"), device=device)
    generator = torch.Generator(device="cpu").manual_seed(cfg_seed(cfg))
    for start in tqdm(range(0, len(state), batch_size), desc="R&D target statistics", leave=False):
        sl = slice(start, start + batch_size)
        a_gt = model.action_stats.normalize(a[sl]).clamp(-1, 1)
        b = a_gt.shape[0]
        k = torch.randint(0, cfg.num_train_timesteps, (b,), generator=generator).to(device)
        eps = torch.randn(a_gt.shape, generator=generator).to(device)
        a_noisy = model.noise_scheduler.add_noise(a_gt, eps, k).clamp(-1, 1)
        T_ee_noisy = pose_from_action(model.action_stats.unnormalize(a_noisy))
        T_now = T_world_ee[sl, -1:]
        t = T_ee_noisy.shape[1]
        _, mask, points, T_cam_obj, T_world_cam = model.render_frames(T_now @ T_ee_noisy, T_now.expand(b, t, 4, 4))
        T_cam_target = invert_transform(T_world_cam) @ (T_now[:, :, None] @ T_ee_target[sl][:, :, None])
        disp = displacement_target(points, T_cam_obj, T_cam_target)  # (b, T, C, 3, h, w)
        m = (mask & valid[sl][:, :, None, None, None]).unsqueeze(3)
        per_cam = disp.permute(2, 3, 0, 1, 4, 5).reshape(n_cam, 3, -1)
        per_cam_mask = m.expand_as(disp).permute(2, 3, 0, 1, 4, 5).reshape(n_cam, 3, -1)
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
    return {
        "action_min": a_min,
        "action_max": a_max,
        "displacement_min": d_min[..., None, None],
        "displacement_max": d_max[..., None, None],
    }


def cfg_seed(cfg) -> int:
    return int(getattr(cfg, "stats_seed", 0))
