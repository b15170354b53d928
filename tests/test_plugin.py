"""The package as a LeRobot plugin: discovery, registration, config round trip and validation."""

import importlib.metadata
import json
import subprocess
import sys

import pytest


def test_distribution_is_discovered_the_way_lerobot_does_it():
    # LeRobot imports every distribution whose metadata Name starts with `lerobot_policy_`, by that name.
    names = {d.metadata.get("Name") for d in importlib.metadata.distributions()}
    assert "lerobot_policy_rnd" in names, "install the project first: pip install -e '.[test]'"
    code = (
        "import sys\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "from lerobot.configs.policies import PreTrainedConfig\n"
        "assert 'rnd' not in PreTrainedConfig.get_known_choices()\n"
        "register_third_party_plugins()\n"
        "assert 'rnd' in PreTrainedConfig.get_known_choices(), PreTrainedConfig.get_known_choices()\n"
        "from lerobot.policies.factory import get_policy_class, _make_processors_from_policy_config\n"
        "cls = get_policy_class('rnd')\n"
        "assert cls.__name__ == 'RnDPolicy' and cls.name == 'rnd', cls\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr[-3000:]


def test_plugin_discovery_registers_the_environments_and_embodiment_presets():
    """LeRobot's discovery (the `lerobot_policy_rnd` shim) registers --env.type=rnd_mw / rnd_panda and the
    simulator presets, with no extra flags; importing lerobot_rnd alone does not."""
    code = (
        "import sys\n"
        "from lerobot.envs.configs import EnvConfig\n"
        "import lerobot_rnd\n"
        "from lerobot_rnd.embodiment import EMBODIMENT_PRESETS\n"
        "assert 'rnd_mw' not in EnvConfig.get_known_choices() and not EMBODIMENT_PRESETS\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "register_third_party_plugins()\n"
        "assert {'rnd_mw', 'rnd_panda'} <= set(EnvConfig.get_known_choices()), EnvConfig.get_known_choices()\n"
        "assert {'metaworld_sawyer', 'metaworld_sawyer_lerobot', 'panda_robotiq'} <= set(EMBODIMENT_PRESETS)\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr[-3000:]


def test_config_round_trips_through_json(tmp_path):
    from lerobot.configs.policies import PreTrainedConfig

    from lerobot_rnd.configuration_rnd import RnDConfig

    cfg = RnDConfig(
        device="cpu",
        variant="I",
        dim_model=64,
        n_layers=1,
        n_heads=4,
        chunk_size=6,
        n_action_steps=3,
        cameras={"observation.images.front": {"K": [[100.0, 0, 63.5], [0, 100.0, 63.5], [0, 0, 1]],
                                              "image_size": [128, 128], "T_world_cam": None,
                                              "T_ee_cam": [[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                                              "mesh": "fingers"}},
        ee_pose={"position_indices": [0, 1, 2], "rotation": "fixed", "gripper_index": 3},
        image_size=(96, 64),
        patch_size=16,
        render_texture=False,
    )
    cfg.save_pretrained(tmp_path)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["type"] == "rnd" and saved["variant"] == "I"
    loaded = PreTrainedConfig.from_pretrained(tmp_path)
    assert isinstance(loaded, RnDConfig)
    for name in ("variant", "dim_model", "n_layers", "chunk_size", "n_action_steps", "cameras", "ee_pose",
                 "render_texture", "patch_size"):
        assert getattr(loaded, name) == getattr(cfg, name), name
    assert tuple(loaded.image_size) == (96, 64)
    assert loaded.observation_delta_indices == [-1, 0]
    assert loaded.action_delta_indices == list(range(-1, 6))  # the step before the chunk first (anchor.py)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"variant": "B"}, "variant"),
        ({"n_action_steps": 9, "chunk_size": 8}, "n_action_steps"),
        ({"num_inference_steps": 0}, "num_inference_steps"),
        ({"dim_model": 100, "n_heads": 16}, "divisible"),
        ({"image_size": (100, 128)}, "image_size"),
        ({"patch_embed": "conv", "patch_size": 12, "image_size": (96, 96)}, "patch_embed"),
        ({"point_update": "svd"}, "point_update"),
        ({"normalization_mapping": {"STATE": "MEAN_STD"}}, "IDENTITY"),
    ],
)
def test_config_rejects_bad_values_with_a_clear_message(kwargs, message):
    from lerobot_rnd.configuration_rnd import RnDConfig

    with pytest.raises(ValueError, match=message):
        RnDConfig(device="cpu", **kwargs)


def test_config_is_lean_and_every_field_is_documented():
    """At most 36 fields (LeRobot's ACT has 23, Diffusion Policy 37, counting n_obs_steps), each named in the
    class docstring's Args, as LeRobot's configs document theirs. (36 since `diffusion_space`: retiring
    `point_update` instead would refuse the backward-compatibility fixture, a checkpoint that samples with "ddim".)"""
    import dataclasses

    from lerobot.configs.policies import PreTrainedConfig

    from lerobot_rnd.configuration_rnd import RETIRED_FIELDS, RnDConfig

    base = {f.name for f in dataclasses.fields(PreTrainedConfig)} - {"n_obs_steps"}
    own = [f.name for f in dataclasses.fields(RnDConfig) if f.name not in base]
    assert len(own) <= 36, len(own)
    args = RnDConfig.__doc__.split("Args:")[1]
    undocumented = [name for name in own if f"{name}:" not in args and f"{name}," not in args]
    assert not undocumented
    assert not set(own) & set(RETIRED_FIELDS)
