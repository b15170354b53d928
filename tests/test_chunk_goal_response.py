"""benchmarks/chunk_goal_response.py: slopes checked on hand-computed displacements, and a run on the toy dataset."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import benchmarks.chunk_goal_response as cgr


def test_a_policy_that_copies_the_demos_has_slope_one():
    demo = np.array([[0.0, 1.0], [2.0, -1.0], [4.0, 3.0]])
    s = cgr.response_stats(demo.copy(), demo)
    assert s["slope"] == pytest.approx([1.0, 1.0]) and s["correlation"] == pytest.approx([1.0, 1.0])
    assert s["mean_abs_error"] == pytest.approx([0.0, 0.0])


def test_half_the_motion_plus_an_offset():
    demo = np.array([[0.0], [2.0], [4.0]])
    s = cgr.response_stats(0.5 * demo + 3.0, demo)  # pred 3, 4, 5: errors 3, 2, 1
    assert s["slope"] == pytest.approx([0.5]) and s["correlation"] == pytest.approx([1.0])
    assert s["mean_abs_error"] == pytest.approx([2.0])
    assert s["demo_displacement_std"] == pytest.approx([np.std([0.0, 2.0, 4.0])])


def test_one_motion_for_every_goal_has_slope_zero_and_no_correlation():
    demo = np.array([[-3.0, 1.0], [0.0, 1.0], [3.0, 1.0]])
    s = cgr.response_stats(np.full((3, 2), 0.7), demo)
    assert s["slope"][0] == pytest.approx(0.0) and s["correlation"][0] is None
    assert s["slope"][1] is None  # the demos do not move this joint differently: nothing to follow


def saved_policy(toy_dataset_root, tmp_path, **overrides):
    """A fresh R&D policy for the toy dataset, saved with its processors: (policy, dataset meta, checkpoint dir)."""
    from lerobot.policies.factory import make_pre_post_processors

    from tests.helpers import make_policy

    policy, meta = make_policy(toy_dataset_root, **overrides)
    pre, post = make_pre_post_processors(policy.config, dataset_stats=meta.stats)
    ckpt = tmp_path / "ckpt"
    for obj in (policy, pre, post):
        obj.save_pretrained(ckpt)
    return policy, meta, ckpt


def test_runs_on_a_saved_policy_and_its_demos(toy_dataset_root, tmp_path):
    policy, meta, ckpt = saved_policy(toy_dataset_root, tmp_path)
    out = tmp_path / "cgr.json"
    assert cgr.main(["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id",
                     "local/toy_reach", "--frames", "0,2", "--draws", "2", "--out", str(out)]) == 0  # fmt: skip
    result = json.loads(out.read_text())
    assert [r["start_frame"] for r in result["rows"]] == [0, 2]
    assert all(r["episodes"] == meta.total_episodes for r in result["rows"])
    assert len(result["rows"][0]["slope"]) == len(result["joint_names"]) == meta.features["action"]["shape"][0]
    assert result["n_obs_steps"] == policy.config.n_obs_steps and "chunk_goal_response.py" in result["command"]


@pytest.mark.parametrize("still", [False, True])
def test_still_history_and_sampler_steps_reach_the_policy(toy_dataset_root, tmp_path, monkeypatch, still):
    """--still-history feeds the current frame as the past one (the state history the policy sees is constant);
    without it the past frame differs. --policy-arg sets the sampler the policy is built with."""
    from lerobot_rnd.modeling_rnd import RnDPolicy

    _, _, ckpt = saved_policy(toy_dataset_root, tmp_path, n_obs_steps=2)
    seen = []
    original = RnDPolicy.predict_action_chunk

    def spy(self, batch, noise=None):
        seen.append((batch["observation.state"].clone(), len(self.model.inference_timesteps)))
        return original(self, batch, noise)

    monkeypatch.setattr(RnDPolicy, "predict_action_chunk", spy)
    out = tmp_path / "cgr.json"
    argv = ["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id", "local/toy_reach",
            "--frames", "3", "--draws", "1", "--policy-arg", "num_inference_steps=3", "--out", str(out)]  # fmt: skip
    assert cgr.main(argv + (["--still-history"] if still else [])) == 0
    states = torch.cat([s for s, _ in seen])  # (episodes, history 2, state dim)
    assert states.shape[1] == 2
    same = torch.isclose(states[:, 0], states[:, 1]).all(dim=-1)
    assert bool(same.all()) if still else not bool(same.any())
    assert {steps for _, steps in seen} == {3}
    result = json.loads(out.read_text())
    assert result["still_history"] is still and result["policy_args"] == ["num_inference_steps=3"]


def test_delta_actions_compare_summed_steps(toy_dataset_root, tmp_path):
    """--delta-actions: the demo's displacement is the sum of its actions over the executed steps (here checked
    against the dataset's parquet, read with pandas), and the policy's is the sum of its chunk's executed steps."""
    import pandas as pd
    policy, _, ckpt = saved_policy(toy_dataset_root, tmp_path)
    out = tmp_path / "cgr.json"
    assert cgr.main(["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id",
                     "local/toy_reach", "--frames", "0", "--draws", "2", "--delta-actions", "--out", str(out)]) == 0  # fmt: skip
    result = json.loads(out.read_text())
    k = policy.config.n_action_steps
    frames = pd.concat([pd.read_parquet(f) for f in sorted(toy_dataset_root.glob("data/**/*.parquet"))])
    sums = np.array([np.stack(g.sort_values("frame_index")["action"].to_numpy()[:k]).sum(0)
                     for _, g in frames.groupby("episode_index")])  # fmt: skip
    assert result["delta_actions"] is True
    assert result["rows"][0]["demo_displacement_std"] == pytest.approx(sums.std(0).tolist(), abs=1e-5)


def test_diffusion_policy_chunk_is_the_one_its_own_select_action_plans(toy_dataset_root, tmp_path):
    """Diffusion Policy keeps its history in a queue that `select_action` fills: the script's chunk for frames
    (t-1, t) must be the chunk LeRobot's own rollout path plans at t after seeing t-1, with the same noise."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.utils.constants import ACTION

    ds = LeRobotDataset("local/toy_reach", root=toy_dataset_root)
    features = dataset_to_policy_features(ds.meta.features)
    cfg = DiffusionConfig(n_obs_steps=2, horizon=8, n_action_steps=4, down_dims=(16, 32), diffusion_step_embed_dim=16,
                          num_inference_steps=2, crop_shape=None, pretrained_backbone_weights=None, device="cpu")
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    policy = DiffusionPolicy(cfg).eval()
    pre, _ = make_pre_post_processors(cfg, dataset_stats=ds.meta.stats)
    past = [ds[2], ds[3]]

    torch.manual_seed(5)
    chunk = cgr.predict_chunk(policy, pre, past, draws=2)

    policy.reset()
    with torch.no_grad():
        policy.select_action(pre(cgr.frame_batch(past[0], 2)))  # sees t-1 (and plans from a repeated t-1)
        policy._queues[ACTION].clear()  # so that the next call plans at t
        torch.manual_seed(5)
        first = policy.select_action(pre(cgr.frame_batch(past[1], 2)))
    reference = torch.stack([first, *policy._queues[ACTION]], dim=1)  # (draws, n_action_steps, A)
    assert chunk.shape == reference.shape == (2, 4, ds.meta.features["action"]["shape"][0])
    torch.testing.assert_close(chunk, reference)


@pytest.fixture(scope="module")
def two_task_root(tmp_path_factory):
    """Paired episodes that start from identical observations and go opposite ways (only the task tells them apart)."""
    from lerobot_rnd.testing import TOY_TASK, record_toy_dataset

    return record_toy_dataset(tmp_path_factory.mktemp("two_tasks") / "toy", n_episodes=2, episode_len=8,
                              tasks=(TOY_TASK, "move away from the red target"))  # fmt: skip


@pytest.mark.parametrize("conditioned", [True, False])
def test_other_task_feeds_the_same_noise_so_only_the_task_token_can_change_the_chunk(two_task_root, tmp_path,
                                                                                      conditioned):
    """--other-task: a policy without task conditioning, fed the other task's string with the same noise, predicts
    exactly the same chunk (task_effect 0); with conditioning the token changes it. Had the noise differed, the
    unconditioned policy's effect would not be 0."""
    _, _, ckpt = saved_policy(two_task_root, tmp_path, task_conditioning=conditioned)
    out = tmp_path / "cgr.json"
    assert cgr.main(["--policy-path", str(ckpt), "--dataset-root", str(two_task_root), "--repo-id", "local/toy_reach",
                     "--frames", "0", "--draws", "2", "--delta-actions", "--other-task", "--out", str(out)]) == 0  # fmt: skip
    row = json.loads(out.read_text())["rows"][0]
    assert row["episodes"] == 4 and len(row["other_task"]["slope"]) == len(row["task_effect"]) == 4
    if conditioned:
        assert max(row["task_effect"]) > 1e-4
    else:
        assert row["task_effect"] == [0.0] * 4 and row["other_task"]["slope"] == row["slope"]


def test_other_task_refuses_a_dataset_of_one_task(toy_dataset_root, tmp_path):
    _, _, ckpt = saved_policy(toy_dataset_root, tmp_path)
    with pytest.raises(SystemExit):
        cgr.main(["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id", "local/toy_reach",
                  "--other-task", "--out", str(tmp_path / "x.json")])  # fmt: skip
