"""The `rnd` policy through LeRobot's own entry points: construction, training, checkpoints, processors, Hub."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from tests.helpers import make_policy, tiny_policy_flags, training_batch


def test_training_batch_shapes_and_loss(toy_dataset_root):
    policy, _ = make_policy(toy_dataset_root)
    batch = training_batch(toy_dataset_root, policy.config)
    assert batch["observation.images.front"].shape == (4, 2, 3, 64, 64)
    assert batch["action"].shape == (4, 1 + 4, 4)  # the step before the chunk first (anchor.py)
    policy.train()
    loss, info = policy.forward(batch)
    assert loss.ndim == 0 and torch.isfinite(loss)
    assert set(info) == {"image_loss", "action_loss", "gripper_loss"}
    loss.backward()
    grads = [p.grad for p in policy.get_optim_params() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)


@pytest.mark.parametrize("variant", ["A", "I", "AI"])
def test_select_action_and_chunk_shapes(toy_dataset_root, variant):
    policy, _ = make_policy(toy_dataset_root, variant=variant)
    policy.eval()
    obs = {
        "observation.images.front": torch.rand(3, 3, 64, 64),
        "observation.images.wrist": torch.rand(3, 3, 64, 64),
        "observation.state": torch.tensor([[0.0, 0.0, 0.2, 1.0]]).repeat(3, 1),
    }
    chunk = policy.predict_action_chunk(obs)  # works on its own, no queues
    assert chunk.shape == (3, 4, 4) and torch.isfinite(chunk).all()
    policy.reset()
    a0 = policy.select_action(obs)
    a1 = policy.select_action(obs)
    assert a0.shape == (3, 4) and a1.shape == (3, 4)
    assert len(policy._queues["action"]) == 0  # n_action_steps = 2 consumed


def test_a_missing_camera_is_named_with_the_flag_that_fixes_it(toy_dataset_root):
    policy, _ = make_policy(toy_dataset_root)
    policy.eval()
    obs = {"observation.images.front": torch.rand(1, 3, 64, 64), "observation.state": torch.zeros(1, 4)}
    with pytest.raises(KeyError, match=r"lacks \['observation.images.wrist'\]") as err:
        policy.predict_action_chunk(obs)
    assert "--env.camera_names=[front,wrist]" in str(err.value)


def test_save_pretrained_round_trip_is_bit_identical(toy_dataset_root, tmp_path):
    from lerobot_rnd.modeling_rnd import RnDPolicy

    policy, _ = make_policy(toy_dataset_root)
    policy.save_pretrained(tmp_path)
    config = json.loads((tmp_path / "config.json").read_text())
    assert set(config["cameras"]) == {"observation.images.front", "observation.images.wrist"}
    assert config["mesh_shapes"]["full"][1] > 0
    # The checkpoint must not depend on the dataset's embodiment file.
    config["embodiment"] = str(tmp_path / "does_not_exist.json")
    (tmp_path / "config.json").write_text(json.dumps(config))
    reloaded = RnDPolicy.from_pretrained(tmp_path)
    obs = {
        "observation.images.front": torch.rand(2, 2, 3, 64, 64),
        "observation.images.wrist": torch.rand(2, 2, 3, 64, 64),
        "observation.state": torch.tensor([0.02, -0.01, 0.2, 1.0]).repeat(2, 2, 1),
    }
    noise = torch.randn(2, 4, 6)
    a = policy.predict_action_chunk(dict(obs), noise=noise)
    b = reloaded.predict_action_chunk(dict(obs), noise=noise)
    assert torch.equal(a, b)
    for name, buf in policy.model.state_dict().items():
        assert torch.equal(buf, reloaded.model.state_dict()[name]), name


def test_loading_with_the_dataset_keeps_the_checkpoints_statistics_and_does_not_estimate_them(toy_dataset_root,
                                                                                             tmp_path, monkeypatch):
    """LeRobot's make_policy passes the dataset's metadata to from_pretrained (`lerobot-train --resume=true`): the
    checkpoint's statistics are loaded, not estimated again from the dataset first; a policy built from scratch
    still estimates them."""
    from lerobot_rnd.modeling_rnd import RnDModel, RnDPolicy

    policy, meta = make_policy(toy_dataset_root)
    policy.model.action_stats.set(policy.model.action_stats.min - 0.5, policy.model.action_stats.max + 0.5)
    policy.save_pretrained(tmp_path)  # statistics no estimate from the dataset would give
    calls = []
    monkeypatch.setattr(RnDModel, "fit_statistics", lambda self, dataset_meta: calls.append(dataset_meta))
    reloaded = RnDPolicy.from_pretrained(tmp_path, dataset_meta=meta)
    assert calls == []
    for name, buf in policy.model.state_dict().items():
        assert torch.equal(buf, reloaded.model.state_dict()[name]), name
    RnDPolicy(reloaded.config, dataset_meta=meta)  # from scratch, after a load: estimated as before
    assert calls == [meta]


def _lerobot_train(tmp_path, root, *extra, steps=2):
    out = tmp_path / "train"
    cmd = [
        "lerobot-train",
        "--policy.type=rnd",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--dataset.repo_id=local/toy_reach",
        f"--dataset.root={root}",
        f"--output_dir={out}",
        f"--steps={steps}",
        f"--save_freq={steps}",
        "--batch_size=2",
        "--num_workers=0",
        "--log_freq=1",
        "--eval_freq=0",
        "--wandb.enable=false",
        *tiny_policy_flags(),
        *extra,
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(tmp_path / "hf")}
    bin_dir = Path(sys.executable).parent
    cmd[0] = str(bin_dir / cmd[0])
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path), out


def test_lerobot_train_writes_a_checkpoint_that_lerobot_loads(toy_dataset_root, tmp_path):
    result, out = _lerobot_train(tmp_path, toy_dataset_root)
    assert result.returncode == 0, result.stderr[-4000:]
    ckpt = out / "checkpoints" / "last" / "pretrained_model"
    for name in ("config.json", "model.safetensors", "policy_preprocessor.json", "policy_postprocessor.json",
                 "train_config.json"):
        assert (ckpt / name).is_file(), name

    # Load it the way lerobot-eval does, in a fresh process with only the plugin discovery.
    code = f"""
import torch
from lerobot.utils.import_utils import register_third_party_plugins
register_third_party_plugins()
from lerobot.configs.policies import PreTrainedConfig
from lerobot.envs.configs import EnvConfig
from lerobot.policies.factory import make_policy, make_pre_post_processors
from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
cfg = PreTrainedConfig.from_pretrained("{ckpt}")
cfg.pretrained_path = "{ckpt}"
meta = LeRobotDatasetMetadata("local/toy_reach", root="{toy_dataset_root}")
policy = make_policy(cfg, ds_meta=meta)
pre, post = make_pre_post_processors(cfg, pretrained_path="{ckpt}",
    preprocessor_overrides={{"device_processor": {{"device": "cpu"}}}})
obs = {{"observation.images.front": torch.rand(3, 64, 64), "observation.images.wrist": torch.rand(3, 64, 64),
       "observation.state": torch.tensor([0.0, 0.0, 0.2, 1.0])}}
action = post(policy.select_action(pre(obs)))
assert action.shape == (1, 4), action.shape
print("loaded-ok", type(policy).__name__)
"""
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0 and "loaded-ok RnDPolicy" in res.stdout, res.stderr[-4000:]


def test_lerobot_train_without_repo_id_fails_early_naming_the_flag(toy_dataset_root, tmp_path):
    result, out = _lerobot_train(tmp_path, toy_dataset_root, "--policy.push_to_hub=true")
    assert result.returncode != 0
    assert "policy.repo_id" in (result.stderr + result.stdout)
    assert not (out / "checkpoints").exists()


def test_push_to_hub_runs_the_real_code_path_against_a_fake_hub(toy_dataset_root, tmp_path, monkeypatch):
    """`push_model_to_hub` with HfApi replaced by a local fake: the pushed folder reloads and its card names R&D."""
    import lerobot.policies.pretrained as pretrained_mod
    from lerobot.configs.default import DatasetConfig
    from lerobot.configs.train import TrainPipelineConfig

    from lerobot_rnd.modeling_rnd import RnDPolicy

    hub = tmp_path / "hub"

    class FakeRepoUrl:
        def __init__(self, url):
            self.url = url

    class FakeCommit:
        def __init__(self, url):
            self.repo_url = FakeRepoUrl(url)

    class FakeHfApi:
        def create_repo(self, repo_id, private=None, exist_ok=False, **kwargs):
            (hub / repo_id).mkdir(parents=True, exist_ok=True)
            return type("Repo", (), {"repo_id": repo_id})()

        def upload_folder(self, repo_id, folder_path, allow_patterns=None, **kwargs):
            import fnmatch
            import shutil

            for f in Path(folder_path).rglob("*"):
                if f.is_file() and any(fnmatch.fnmatch(f.name, p) for p in allow_patterns):
                    shutil.copy(f, hub / repo_id / f.name)
            return FakeCommit(f"file://{hub / repo_id}")

    monkeypatch.setattr(pretrained_mod, "HfApi", FakeHfApi)
    policy, _ = make_policy(toy_dataset_root)
    policy.config.repo_id = "someone/rnd_toy"
    train_cfg = TrainPipelineConfig(dataset=DatasetConfig(repo_id="local/toy_reach"), policy=policy.config)
    monkeypatch.setattr(sys, "argv", ["lerobot-train", "--policy.type=rnd", "--dataset.repo_id=local/toy_reach"])
    policy.push_model_to_hub(train_cfg)

    pushed = hub / "someone/rnd_toy"
    card = (pushed / "README.md").read_text()
    assert "Render and Diffuse" in card and "2405.18196" in card and "R&D-AI" in card
    assert "lerobot-train --policy.type=rnd --dataset.repo_id=local/toy_reach" in card
    assert "not recognized" not in card
    reloaded = RnDPolicy.from_pretrained(pushed)
    assert torch.equal(reloaded.model.meshes.vertices, policy.model.meshes.vertices)


def test_processors_are_saved_and_reloaded(toy_dataset_root, tmp_path):
    from lerobot.policies.factory import make_pre_post_processors

    policy, meta = make_policy(toy_dataset_root)
    pre, post = make_pre_post_processors(policy.config, dataset_stats=meta.stats)
    pre.save_pretrained(tmp_path)
    post.save_pretrained(tmp_path)
    pre2, post2 = make_pre_post_processors(policy.config, pretrained_path=str(tmp_path))
    obs = {"observation.images.front": torch.rand(3, 64, 64), "observation.images.wrist": torch.rand(3, 64, 64),
           "observation.state": torch.tensor([0.01, 0.02, 0.2, 1.0])}
    a, b = pre(dict(obs)), pre2(dict(obs))
    for key in obs:
        assert torch.equal(a[key], b[key]), key
    # IDENTITY normalisation: R&D sees the raw metric state.
    assert torch.equal(a["observation.state"][0], obs["observation.state"])
    assert [s.__class__.__name__ for s in pre2.steps] == [s.__class__.__name__ for s in pre.steps]


def test_bad_inputs_get_errors_that_name_the_fix(toy_dataset_root):
    policy, _ = make_policy(toy_dataset_root)
    obs = {"observation.images.front": torch.rand(1, 3, 64, 64),
           "observation.images.side": torch.rand(1, 3, 64, 64),
           "observation.state": torch.tensor([[0.0, 0.0, 0.2, 1.0]])}
    with pytest.raises(KeyError, match="rename_map"):
        policy.select_action(obs)

    obs = {"observation.images.front": torch.rand(1, 3, 64, 64), "observation.images.wrist": torch.rand(1, 3, 64, 64),
           "observation.state": torch.tensor([[float("nan"), 0.0, 0.2, 1.0]])}
    with pytest.raises(ValueError, match="NaN"):
        policy.predict_action_chunk(obs)

    obs["observation.state"] = torch.tensor([[0.0, 0.0, 0.2, 1.0]])
    obs["observation.images.front"] = torch.rand(1, 3, 64, 48)
    with pytest.raises(ValueError, match="aspect ratio"):
        policy.predict_action_chunk(obs)

    # Missing calibration for a camera of the dataset.
    with pytest.raises(ValueError, match="no calibration for"):
        _make_policy_with_features(toy_dataset_root, extra_image="observation.images.side")
    # Image size that does not match the calibration.
    with pytest.raises(ValueError, match=r"resized\(32, 32\)"):
        _make_policy_with_features(toy_dataset_root, front_shape=(3, 32, 32))
    # Action dimension that does not match the dataset.
    with pytest.raises(ValueError, match="action adapter"):
        _make_policy_with_features(toy_dataset_root, action_dim=7)
    # No embodiment at all.
    with pytest.raises(ValueError, match="--policy.embodiment"):
        _make_policy_with_features(toy_dataset_root, no_embodiment=True)


def _make_policy_with_features(root, extra_image=None, front_shape=None, action_dim=None, no_embodiment=False):
    from lerobot.configs.types import FeatureType, PolicyFeature

    features = {}
    if extra_image:
        features[extra_image] = PolicyFeature(type=FeatureType.VISUAL, shape=(3, 64, 64))
    if front_shape:
        features["observation.images.front"] = PolicyFeature(type=FeatureType.VISUAL, shape=front_shape)
    if action_dim:
        features["action"] = PolicyFeature(type=FeatureType.ACTION, shape=(action_dim,))
    return make_policy(root, features=features, with_dataset_meta=not no_embodiment)[0]
