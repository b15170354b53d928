"""The failure table (docs/FAILURES.md): what R&D does with bad input, one test per row.

Every row is either a clear error that names the field and the fix, raised before any long work starts, or a
documented fallback. Rows already tested elsewhere are listed in docs/FAILURES.md with their test.
"""

import copy
import json
import shutil
import sys
import warnings

import numpy as np
import pytest
import torch

from tests.helpers import FIXTURE_CHECKPOINT, make_policy
from lerobot_rnd.testing import toy_embodiment


def _write(tmp_path, d, name="emb.json"):
    path = tmp_path / name
    path.write_text(json.dumps(d))
    return path


def _load(path):
    from lerobot_rnd.embodiment import load_embodiment

    return load_embodiment(str(path))


# --------------------------------------------------------------------------------------------------
# Embodiment description
# --------------------------------------------------------------------------------------------------
def test_embodiment_missing_file_lists_presets(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"neither a preset \(.*metaworld_sawyer"):
        _load(tmp_path / "nope.json")


def test_embodiment_unknown_preset_lists_presets():
    with pytest.raises(FileNotFoundError, match=r"'panda_robotiqq' is neither a preset \(.*panda_robotiq"):
        _load("panda_robotiqq")


def test_embodiment_invalid_json_names_file_and_line(tmp_path):
    path = tmp_path / "emb.json"
    path.write_text('{"cameras": {,}}')
    with pytest.raises(ValueError, match=r"emb\.json: not valid JSON \(.* line 1, column 14\)"):
        _load(path)


def test_embodiment_misspelt_key_is_refused_with_a_suggestion(tmp_path):
    d = toy_embodiment().to_dict()
    d["camerass"] = d.pop("cameras")
    with pytest.raises(
        ValueError, match=r"emb\.json: .*unknown key\(s\) 'camerass' \(did you mean 'cameras'\?\)"
    ):
        _load(_write(tmp_path, d))


def test_embodiment_unknown_camera_key_is_refused(tmp_path):
    d = toy_embodiment().to_dict()
    d["cameras"]["observation.images.front"]["fx"] = 50.0
    with pytest.raises(ValueError, match=r"emb\.json: camera calibration: unknown keys \['fx'\]"):
        _load(_write(tmp_path, d))


def test_embodiment_non_rigid_extrinsics_are_refused(tmp_path):
    d = toy_embodiment().to_dict()
    T = np.asarray(d["cameras"]["observation.images.front"]["T_world_cam"])
    T[:3, :3] *= 1.5  # a scaled rotation
    d["cameras"]["observation.images.front"]["T_world_cam"] = T.tolist()
    with pytest.raises(ValueError, match=r"emb\.json: camera 'front': T_world_cam is not a rigid transform"):
        _load(_write(tmp_path, d))


def test_embodiment_non_finite_extrinsics_are_refused(tmp_path):
    d = toy_embodiment().to_dict()
    d["cameras"]["observation.images.wrist"]["T_ee_cam"][0][3] = float("nan")
    with pytest.raises(ValueError, match=r"camera 'wrist': T_ee_cam .*(NaN|finite)"):
        _load(_write(tmp_path, d))


def test_embodiment_empty_mesh_is_refused(tmp_path):
    d = toy_embodiment().to_dict()
    d["meshes"]["fingers"]["faces"] = []
    with pytest.raises(ValueError, match=r"meshes\['fingers'\] has no faces"):
        _load(_write(tmp_path, d))


def test_embodiment_mesh_file_that_does_not_exist(tmp_path):
    from lerobot_rnd.gripper_mesh import GripperMesh

    with pytest.raises(FileNotFoundError, match=r"mesh file not found: .*finger\.stl"):
        GripperMesh.from_files([tmp_path / "finger.stl"])


def test_open_mesh_is_a_documented_fallback_rendered_as_a_surface(tmp_path, toy_dataset_root):
    """A non-watertight mesh is accepted: the rasteriser draws triangles, it never needs a closed surface."""
    from lerobot_rnd.embodiment import Embodiment

    emb = toy_embodiment()
    full = emb.meshes["full"]
    open_mesh = type(full)(full.vertices, full.faces[: len(full.faces) // 2], full.vertex_colors, full.name)
    assert not open_mesh.to_trimesh().is_watertight
    emb = Embodiment.from_dict(
        {**emb.to_dict(), "meshes": {**emb.to_dict()["meshes"], "full": open_mesh.to_dict()}}
    )
    path = emb.save_json(tmp_path / "open.json")
    policy, _ = make_policy(toy_dataset_root, embodiment=str(path))
    obs = _observation()
    actions = policy.predict_action_chunk(obs, noise=torch.zeros(1, policy.config.chunk_size, 6))
    assert torch.isfinite(actions).all()


# --------------------------------------------------------------------------------------------------
# Dataset and embodiment together
# --------------------------------------------------------------------------------------------------
def test_embodiment_for_another_robot_names_both_camera_sets(toy_dataset_root, tmp_path):
    emb = toy_embodiment()
    other = emb.subset(["observation.images.front"])
    other.cameras = {"observation.images.top": other.cameras["observation.images.front"]}
    other.camera_mesh = {"observation.images.top": "full"}
    path = other.save_json(tmp_path / "other.json")
    with pytest.raises(
        ValueError,
        match=r"calibrates cameras \['observation\.images\.top'\], but the policy's images are "
        r"\['observation\.images\.front', 'observation\.images\.wrist'\] .*another robot",
    ):
        make_policy(toy_dataset_root, embodiment=str(path))


def test_embodiment_camera_the_dataset_lacks_is_ignored(toy_dataset_root, tmp_path):
    """Documented fallback: an embodiment may calibrate more cameras than the dataset has; the rest are unused."""
    emb = toy_embodiment()
    d = emb.to_dict()
    d["cameras"]["observation.images.side"] = {**d["cameras"]["observation.images.front"], "name": "side"}
    path = _write(tmp_path, d)
    policy, _ = make_policy(toy_dataset_root, embodiment=str(path))
    assert sorted(policy.config.cameras) == ["observation.images.front", "observation.images.wrist"]


def test_state_without_the_pose_the_adapter_needs(toy_dataset_root):
    from lerobot.configs.types import FeatureType, PolicyFeature

    short_state = {"observation.state": PolicyFeature(type=FeatureType.STATE, shape=(2,))}
    with pytest.raises(ValueError, match=r"observation\.state"):
        make_policy(toy_dataset_root, features=short_state)


def test_empty_dataset_is_refused_before_statistics(toy_dataset_root, toy_policy):
    """LeRobot itself cannot open a dataset folder without episodes (it has no tasks file); a dataset whose
    metadata reports no frames is refused by R&D before any statistics."""
    from types import SimpleNamespace

    from lerobot_rnd.modeling_rnd import RnDPolicy

    empty = SimpleNamespace(total_frames=0, total_episodes=0, repo_id="local/empty", root=toy_dataset_root)
    config = copy.deepcopy(toy_policy.config)
    with pytest.raises(ValueError, match=r"Dataset local/empty at .* has no frames: record or add episodes"):
        RnDPolicy(config, dataset_meta=empty)


# --------------------------------------------------------------------------------------------------
# The policy at run time
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def toy_policy(toy_dataset_root):
    return make_policy(toy_dataset_root)[0]


def _observation(**changes):
    g = torch.Generator().manual_seed(0)
    obs = {
        "observation.images.front": torch.rand(1, 3, 64, 64, generator=g),
        "observation.images.wrist": torch.rand(1, 3, 64, 64, generator=g),
        "observation.state": torch.tensor([[0.0, 0.0, 0.2, 1.0]]),
    }
    obs.update(changes)
    return obs


def test_nan_pixel_names_the_camera(toy_policy):
    img = torch.rand(1, 3, 64, 64)
    img[0, 1, 5, 7] = float("nan")
    with pytest.raises(ValueError, match=r"observation\.images\.wrist: 1 NaN/Inf pixel value"):
        toy_policy.predict_action_chunk(_observation(**{"observation.images.wrist": img}))


def test_uint8_images_are_converted_like_float_images(toy_policy):
    """Documented fallback: uint8 (0-255) images are divided by 255."""
    g = torch.Generator().manual_seed(1)
    as_uint8 = {
        k: (torch.rand(1, 3, 64, 64, generator=g) * 255).round().to(torch.uint8) for k in ("front", "wrist")
    }
    noise = torch.randn(1, toy_policy.config.chunk_size, 6, generator=g)
    a = toy_policy.predict_action_chunk(
        _observation(**{f"observation.images.{k}": v for k, v in as_uint8.items()}), noise=noise
    )
    b = toy_policy.predict_action_chunk(
        _observation(**{f"observation.images.{k}": v.float() / 255 for k, v in as_uint8.items()}), noise=noise
    )
    torch.testing.assert_close(a, b)


def test_images_in_0_255_as_float_are_refused(toy_policy):
    with pytest.raises(
        ValueError, match=r"observation\.images\.front: pixel values span .* divide 0-255 images"
    ):
        toy_policy.predict_action_chunk(
            _observation(**{"observation.images.front": torch.rand(1, 3, 64, 64) * 255})
        )


def test_integer_images_other_than_uint8_are_refused(toy_policy):
    img = torch.randint(0, 255, (1, 3, 64, 64), dtype=torch.int32)
    with pytest.raises(ValueError, match=r"observation\.images\.front: images must be float .* torch\.int32"):
        toy_policy.predict_action_chunk(_observation(**{"observation.images.front": img}))


def test_gripper_outside_every_camera_gives_a_finite_action_and_warns_once(toy_dataset_root):
    """With only the static camera (a wrist camera always sees the fingers) and the gripper 50 m away."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy
    from tests.helpers import TINY_POLICY_KWARGS

    meta = LeRobotDatasetMetadata("local/toy_reach", root=toy_dataset_root)
    features = dataset_to_policy_features(meta.features)
    cfg = RnDConfig(**TINY_POLICY_KWARGS)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {
        k: f for k, f in features.items() if k in ("observation.images.front", "observation.state")
    }
    policy = RnDPolicy(cfg, dataset_meta=meta)
    far = {k: v for k, v in _observation(**{"observation.state": torch.tensor([[50.0, -40.0, 30.0, 1.0]])}).items()
           if k != "observation.images.wrist"}  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(2):
            actions = policy.predict_action_chunk(far)
            assert torch.isfinite(actions).all()
    messages = [str(w.message) for w in caught if "visible in none of the cameras" in str(w.message)]
    assert len(messages) == 1


# --------------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------------
@pytest.fixture
def checkpoint(tmp_path):
    return shutil.copytree(FIXTURE_CHECKPOINT, tmp_path / "pretrained_model")


def _load_policy(path):
    from lerobot_rnd.modeling_rnd import RnDPolicy

    return RnDPolicy.from_pretrained(path)


def test_truncated_weights_name_the_checkpoint(checkpoint):
    weights = checkpoint / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[: weights.stat().st_size // 3])
    with pytest.raises(
        ValueError, match=r"checkpoint .*pretrained_model: model\.safetensors cannot be read .*damaged"
    ):
        _load_policy(checkpoint)


def test_config_of_another_variant_is_refused(checkpoint):
    config = json.loads((checkpoint / "config.json").read_text())
    config["variant"] = "I"
    (checkpoint / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"does not fit its config\.json \(variant 'I'.*different runs"):
        _load_policy(checkpoint)


def test_checkpoint_without_its_embodiment_asks_for_one(checkpoint):
    config = json.loads((checkpoint / "config.json").read_text())
    config["cameras"], config["mesh_shapes"], config["embodiment"] = {}, {}, None
    (checkpoint / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"--policy\.embodiment=<preset name or embodiment JSON>"):
        _load_policy(checkpoint)


def test_checkpoint_given_another_robots_inputs_says_the_robots_differ(checkpoint):
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.configs.types import FeatureType, PolicyFeature

    config = PreTrainedConfig.from_pretrained(checkpoint)
    config.input_features = {  # what a 7-D Panda env with other camera names would give
        "observation.images.front_cam": PolicyFeature(type=FeatureType.VISUAL, shape=(3, 64, 64)),
        "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(8,)),
    }
    config.output_features = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(7,))}
    from lerobot_rnd.modeling_rnd import RnDPolicy

    with pytest.raises(
        ValueError, match=r"4-D actions .* given cameras .* 7-D actions: the checkpoint's robot and"
    ):
        RnDPolicy.from_pretrained(checkpoint, config=config)


def test_saved_checkpoint_has_no_local_path_and_a_model_card(toy_dataset_root, tmp_path):
    policy, _ = make_policy(toy_dataset_root)
    assert policy.config.embodiment.endswith("rnd_embodiment.json")  # resolved from the dataset
    policy.save_pretrained(tmp_path / "ckpt")
    saved = json.loads((tmp_path / "ckpt" / "config.json").read_text())
    assert saved["embodiment"] is None and saved["cameras"]
    assert str(toy_dataset_root) not in (tmp_path / "ckpt" / "config.json").read_text()
    assert policy.config.embodiment.endswith("rnd_embodiment.json")  # the live config is unchanged
    card = (tmp_path / "ckpt" / "README.md").read_text()
    assert "Render and Diffuse" in card and "R&D-AI" in card
    reloaded = _load_policy(tmp_path / "ckpt")
    assert reloaded.config.cameras == policy.config.cameras


# --------------------------------------------------------------------------------------------------
# Hub push and configuration
# --------------------------------------------------------------------------------------------------
class _StopBeforeStatistics(Exception):
    pass


def _no_statistics(monkeypatch):
    from lerobot_rnd.modeling_rnd import RnDModel

    def fail(self, dataset_meta):
        raise _StopBeforeStatistics

    monkeypatch.setattr(RnDModel, "fit_statistics", fail)


def test_push_to_hub_offline_fails_before_training(toy_dataset_root, monkeypatch):
    _no_statistics(monkeypatch)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(RuntimeError, match=r"push_to_hub=true .*\(HF_HUB_OFFLINE=1\).*push_to_hub=false"):
        make_policy(toy_dataset_root, push_to_hub=True, repo_id="someone/rnd-test")


def _online(monkeypatch):
    from huggingface_hub import constants

    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    if hasattr(constants, "is_offline_mode"):
        monkeypatch.setattr(constants, "is_offline_mode", lambda: False)


def test_push_to_hub_unreachable_repo_fails_before_training(toy_dataset_root, monkeypatch):
    from huggingface_hub import HfApi

    _no_statistics(monkeypatch)
    _online(monkeypatch)

    def refuse(self, repo_id, **kwargs):
        raise PermissionError("401 Unauthorized")

    monkeypatch.setattr(HfApi, "create_repo", refuse)
    with pytest.raises(
        RuntimeError, match=r"'someone/rnd-test' cannot be reached or created \(401 Unauthorized\)"
    ):
        make_policy(toy_dataset_root, push_to_hub=True, repo_id="someone/rnd-test")


def test_push_to_hub_creates_the_repo_before_the_statistics(toy_dataset_root, monkeypatch):
    from huggingface_hub import HfApi

    _no_statistics(monkeypatch)
    _online(monkeypatch)
    created = []
    monkeypatch.setattr(HfApi, "create_repo", lambda self, repo_id, **kw: created.append(repo_id))
    with pytest.raises(_StopBeforeStatistics):
        make_policy(toy_dataset_root, push_to_hub=True, repo_id="someone/rnd-test")
    assert created == ["someone/rnd-test"]


def test_unknown_variant_is_the_last_line_of_the_cli_error():
    import draccus

    from lerobot_rnd.cli_errors import config_error_line
    from lerobot_rnd.configuration_rnd import RnDConfig

    with pytest.raises(Exception) as info:
        draccus.parse(RnDConfig, args=["--variant=X"])
    assert "Couldn't instantiate" in str(info.value)  # draccus's own last line says nothing useful
    line = config_error_line(info.value)
    assert line is not None and "variant" in line and "'X'" in line


def test_config_error_hook_prints_the_message_last(capsys, monkeypatch):
    import draccus

    from lerobot_rnd import cli_errors
    from lerobot_rnd.configuration_rnd import RnDConfig

    monkeypatch.setattr(sys, "excepthook", sys.__excepthook__)
    cli_errors.install_config_error_hook()
    cli_errors.install_config_error_hook()  # idempotent
    try:
        draccus.parse(RnDConfig, args=["--variant=X"])
    except Exception as exc:  # noqa: BLE001
        sys.excepthook(type(exc), exc, exc.__traceback__)
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: ") and "variant" in err[-1]
    assert sum(line.startswith("error: ") for line in err) == 1


def test_errors_unrelated_to_the_plugin_are_left_alone():
    from lerobot_rnd.cli_errors import config_error_line

    assert config_error_line(ValueError("x")) is None
    try:
        raise RuntimeError("outer") from KeyError("inner")
    except RuntimeError as exc:
        assert config_error_line(exc) is None


# --------------------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------------------
def test_eval_without_env_task_uses_the_checkpoints_task(tmp_path, monkeypatch):
    """`lerobot-eval --policy.path=<ckpt> --env.type=rnd_mw` without --env.task used to run reach-v3 silently."""
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig
    from lerobot_rnd.sim.mujoco_env import task_of_checkpoint_in_argv

    ckpt = tmp_path / "pretrained_model"
    ckpt.mkdir()
    (ckpt / "train_config.json").write_text(
        json.dumps({"env": {"type": "rnd_mw", "task": "drawer-close-v3"}})
    )
    argv = ["lerobot-eval", f"--policy.path={ckpt}", "--env.type=rnd_mw"]
    assert task_of_checkpoint_in_argv(argv[1:]) == ("drawer-close-v3", str(ckpt))
    assert task_of_checkpoint_in_argv([*argv[1:], "--env.task=reach-v3"]) == (None, None)
    assert task_of_checkpoint_in_argv(["--policy.path=someone/on-the-hub"]) == (None, None)

    monkeypatch.setattr(sys, "argv", argv)
    assert RnDMetaWorldEnvConfig().task == "drawer-close-v3"
    monkeypatch.setattr(sys, "argv", [*argv, "--env.task=reach-v3"])
    assert RnDMetaWorldEnvConfig(task="reach-v3").task == "reach-v3"
