"""benchmarks/denoiser_goal_response.py: its demo windows against LeRobot's own, and its estimates on a network
whose answer is known."""

from __future__ import annotations

import json

import pytest
import torch

import benchmarks.denoiser_goal_response as dgr
from tests.test_chunk_goal_response import saved_policy


def test_demo_windows_are_the_ones_lerobot_trains_on(toy_dataset_root):
    """The script builds its windows itself (to feed each one many noise draws); they must be LeRobot's training
    samples at the same frame (its delta-timestamp sampler: history clamped at the episode's start, chunk clamped
    at its end), including the first frame and one whose chunk runs past the end."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from tests.helpers import dataset_items, make_policy

    policy, meta = make_policy(toy_dataset_root, n_obs_steps=2)
    cfg = policy.config
    ds = LeRobotDataset("local/toy_reach", root=toy_dataset_root)
    start, stop = int(meta.episodes[1]["dataset_from_index"]), int(meta.episodes[1]["dataset_to_index"])
    for t0 in (0, 1, stop - start - 2):
        past, actions = dgr.demo_window(ds, start, stop, t0, cfg.n_obs_steps, cfg.chunk_size)
        ref = dataset_items(toy_dataset_root, cfg, [start + t0])
        torch.testing.assert_close(torch.stack([f["observation.state"] for f in past]), ref["observation.state"][0])
        ref_actions = ref["action"][0][-cfg.chunk_size :]  # the dataset may also give the step before the chunk
        torch.testing.assert_close(actions, ref_actions)


def test_an_action_head_that_adds_nothing_follows_the_demos_only_at_step_zero(toy_dataset_root, tmp_path):
    """With the action head's last layer zeroed, its clean estimate is the noisy chunk itself. At k = 0 that is the
    demo plus the schedule's smallest noise (slope 1, error ~ 0: the demo row and the noising line up); at k = K - 1
    it is noise clamped to [-1, 1] and its error is of the order of the demo's spread."""
    policy, meta, ckpt = saved_policy(toy_dataset_root, tmp_path)
    head = policy.model.network.action_head[-1]
    with torch.no_grad():
        head.weight.zero_()
        head.bias.zero_()
    policy.save_pretrained(ckpt)
    rows = {}
    for step in (0, policy.config.num_train_timesteps - 1):
        out = tmp_path / f"dgr_{step}.json"
        argv = ["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id", "local/toy_reach",
                "--frames", "2,3", "--draws", "4", "--step", str(step), "--out", str(out)]  # fmt: skip
        assert dgr.main(argv) == 0
        result = json.loads(out.read_text())
        assert result["step"] == step and "denoiser_goal_response.py" in result["command"]
        rows[step] = result["rows"]
    # the noise left at k = 0 (diffusers' schedule): the estimate averages 4 draws of it
    sigma_0 = float((1 - policy.model.noise_scheduler.alphas_cumprod[0]).sqrt())
    for row, noisiest in zip(rows[0], rows[policy.config.num_train_timesteps - 1], strict=True):
        assert row["episodes"] == meta.total_episodes and set(dgr.SOURCES) <= set(row)
        varying = [i for i, s in enumerate(row["demo_std"]) if s >= dgr.MIN_DEMO_STD]
        assert varying, "the toy demos move differently from frame 2 on"
        assert [row["action_head"]["slope"][i] for i in varying] == pytest.approx([1.0] * len(varying), abs=0.1)
        assert max(row["action_head"]["mean_abs_error"]) < 2 * sigma_0
        for i in varying:
            assert noisiest["action_head"]["mean_abs_error"][i] > 2 * row["action_head"]["mean_abs_error"][i]


def test_refuses_a_policy_that_is_not_rnd(toy_dataset_root, tmp_path):
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.policies.act.configuration_act import ACTConfig

    meta = LeRobotDatasetMetadata("local/toy_reach", root=toy_dataset_root)
    features = dataset_to_policy_features(meta.features)
    cfg = ACTConfig(device="cpu", pretrained_backbone_weights=None)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    cfg.save_pretrained(tmp_path / "act")
    with pytest.raises(SystemExit):
        dgr.main(["--policy-path", str(tmp_path / "act"), "--dataset-root", str(toy_dataset_root), "--repo-id",
                  "local/toy_reach", "--out", str(tmp_path / "x.json")])  # fmt: skip


def test_blank_camera_feeds_that_camera_as_one_colour(toy_dataset_root, tmp_path, monkeypatch):
    """--blank-camera: every image of that camera the model renders over is a single colour (its mean), in the
    history and the current frame alike; an unknown camera key is refused naming the policy's cameras."""
    from lerobot_rnd.modeling_rnd import RnDModel

    policy, _, ckpt = saved_policy(toy_dataset_root, tmp_path)
    camera = next(iter(policy.config.image_features))
    seen = []
    original = RnDModel.render_history

    def spy(self, images, T_world_ee):
        seen.append(images[:, :, list(self.config.image_features).index(camera)].clone())
        return original(self, images, T_world_ee)

    monkeypatch.setattr(RnDModel, "render_history", spy)
    base = ["--policy-path", str(ckpt), "--dataset-root", str(toy_dataset_root), "--repo-id", "local/toy_reach",
            "--frames", "2", "--draws", "1"]  # fmt: skip
    assert dgr.main([*base, "--blank-camera", camera, "--out", str(tmp_path / "b.json")]) == 0
    assert seen and all(float(x.max() - x.min()) < 1e-6 for x in seen)
    seen.clear()
    assert dgr.main([*base, "--out", str(tmp_path / "a.json")]) == 0
    assert all(float(x.max() - x.min()) > 0.05 for x in seen)
    assert json.loads((tmp_path / "b.json").read_text())["blank_camera"] == camera
    with pytest.raises(SystemExit):
        dgr.main([*base, "--blank-camera", "observation.images.nope", "--out", str(tmp_path / "c.json")])
