"""Min/max normalisation of R&D targets and its estimation from a dataset on disk."""

import numpy as np
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
    from tests.toy_data import record_toy_dataset

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
