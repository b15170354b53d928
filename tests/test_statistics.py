"""Min/max normalisation of R&D targets and its estimation from a dataset on disk."""

import numpy as np
import pytest
import torch

from lerobot_rnd.statistics import MinMaxStats, load_episode_arrays, sample_training_windows


def test_min_max_stats_map_the_range_to_plus_minus_one_and_invert():
    x = torch.randn(100, 6) * torch.tensor([1.0, 2.0, 0.1, 5.0, 0.5, 1.0]) + 3.0
    x[:, 5] = 0.25  # a constant feature must stay finite
    stats = MinMaxStats((6,))
    stats.set(x.amin(0), x.amax(0))
    y = stats.normalize(x)
    assert torch.isfinite(y).all()
    torch.testing.assert_close(y[:, :5].amin(0), -torch.ones(5))
    torch.testing.assert_close(y[:, :5].amax(0), torch.ones(5))
    torch.testing.assert_close(y[:, 5], torch.zeros(100), atol=1e-3, rtol=0)
    torch.testing.assert_close(stats.unnormalize(y), x)
    assert set(stats.state_dict()) == {"min", "max"}  # saved with the model


def test_windows_are_clamped_and_padded_like_lerobot(tmp_path):
    from lerobot_rnd.testing import record_toy_dataset

    root = record_toy_dataset(tmp_path / "toy", n_episodes=2, episode_len=5)
    episodes = load_episode_arrays(root)
    assert [len(s) for s, _ in episodes] == [5, 5]
    state, action, pad = sample_training_windows(episodes, n_obs_steps=2, horizon=4, num_samples=200, seed=0)
    assert state.shape == (200, 2, 4) and action.shape == (200, 4, 4) and pad.shape == (200, 4)
    # Windows starting at the last frame pad the 3 future steps and repeat the last action (LeRobot's clamping).
    all_actions = np.concatenate([a for _, a in episodes])
    last_rows = {tuple(a[-1]) for _, a in episodes}
    for i in range(200):
        n_pad = int(pad[i].sum())
        assert pad[i].tolist() == [False] * (4 - n_pad) + [True] * n_pad
        if n_pad:
            assert tuple(action[i, -1].tolist()) in last_rows
        assert any(np.allclose(action[i, 0].numpy(), row) for row in all_actions)


def _reference_action_range(root, horizon):
    """Min/max of the EE-frame translation targets over every window, straight from the parquet files."""
    import pandas as pd
    from pathlib import Path

    from lerobot_rnd.testing import R_WORLD_EE

    frame = pd.concat([pd.read_parquet(f) for f in sorted(Path(root, "data").glob("**/*.parquet"))])
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for _, ep in frame.groupby("episode_index"):
        actions = np.stack(ep.sort_values("frame_index")["action"].to_numpy())
        for i in range(len(actions)):
            window = actions[i : i + horizon, :3]  # padded steps are not targets
            disp_world = np.cumsum(window * 0.01, axis=0)
            disp_ee = disp_world @ R_WORLD_EE  # R^T d for each row
            lo, hi = np.minimum(lo, disp_ee.min(0)), np.maximum(hi, disp_ee.max(0))
    return lo, hi


def test_action_statistics_cover_every_window_with_a_margin(toy_dataset_root):
    from lerobot_rnd.statistics import STATS_MARGIN
    from tests.helpers import make_policy as _make_policy

    policy, _ = _make_policy(toy_dataset_root)
    stats = policy.model.action_stats
    lo, hi = _reference_action_range(toy_dataset_root, policy.config.chunk_size)
    margin = 0.05
    assert STATS_MARGIN == margin
    pad = margin * (hi - lo)
    np.testing.assert_allclose(stats.min[:3].numpy(), lo - pad, atol=1e-6)
    np.testing.assert_allclose(stats.max[:3].numpy(), hi + pad, atol=1e-6)
    # Rotation never changes in the toy data: its range is the minimum one, centred on 0.
    assert torch.allclose(stats.min[3:], -stats.max[3:])
    # So every training target lies strictly inside [-1, 1]: nothing is clamped.
    edge = 1 / (1 + 2 * margin)
    assert np.all(2 * ((hi - (lo - pad)) / ((hi + pad) - (lo - pad))) - 1 <= edge + 1e-6)


def test_gripper_class_weight_is_the_open_closed_ratio(toy_dataset_root):
    from tests.helpers import make_policy as _make_policy

    policy, _ = _make_policy(toy_dataset_root)
    # Toy episodes close the gripper for the second half of every episode: every window's targets count.
    import pandas as pd
    from pathlib import Path

    frame = pd.concat([pd.read_parquet(f) for f in sorted(Path(toy_dataset_root, "data").glob("**/*.parquet"))])
    closed = opened = 0
    t = policy.config.chunk_size
    for _, ep in frame.groupby("episode_index"):
        g = np.stack(ep.sort_values("frame_index")["action"].to_numpy())[:, 3]
        for i in range(len(g)):
            w = g[i : i + t]
            closed += int((w > 0).sum())
            opened += int((w <= 0).sum())
    assert float(policy.model.gripper_pos_weight) == pytest.approx(opened / closed, rel=1e-6)


def test_non_finite_actions_are_refused_with_the_episode_and_frame(tmp_path):
    import pandas as pd
    from pathlib import Path

    from tests.helpers import make_policy as _make_policy
    from lerobot_rnd.testing import record_toy_dataset

    root = record_toy_dataset(tmp_path / "toy_nan", n_episodes=2, episode_len=6)
    files = sorted(Path(root, "data").glob("**/*.parquet"))
    frame = pd.read_parquet(files[0])
    actions = np.stack(frame["action"].to_numpy()).copy()
    row = int(np.flatnonzero(frame["episode_index"].to_numpy() == 1)[2])
    actions[row, 1] = np.nan
    frame["action"] = list(actions)
    frame.to_parquet(files[0])
    with pytest.raises(ValueError, match=r"'action' contains NaN or inf \(episode 1, frame 2"):
        _make_policy(root)
