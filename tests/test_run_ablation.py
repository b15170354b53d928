"""benchmarks/run_ablation.py: a reused checkpoint (--checkpoint ROW=DIR) must have been trained as its row says."""

from __future__ import annotations

import json

import pytest

from benchmarks.run_ablation import ROWS, check_reused_checkpoint, main, trained_switches


def _checkpoint(tmp_path, steps=3000, root="demos", **policy):
    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    cfg = {"steps": steps, "dataset": {"root": str(tmp_path / root)},
           "policy": {"dim_model": 256, "dropout": 0.0, **policy}}  # fmt: skip
    (ckpt / "train_config.json").write_text(json.dumps(cfg))
    return ckpt


def test_a_checkpoint_trained_as_the_row_says_is_accepted_and_refused_for_another_row(tmp_path):
    ckpt = _checkpoint(tmp_path, dim_model=384)
    assert check_reused_checkpoint(ckpt, ROWS["width_384"][0], 3000, tmp_path / "demos") is None
    with pytest.raises(SystemExit, match="policy.dropout is 0.0, the row wants 0.1"):
        check_reused_checkpoint(ckpt, ROWS["dropout_0.1"][0], 3000, tmp_path / "demos")


@pytest.mark.parametrize(
    ("row", "policy", "steps", "root", "message"),
    [
        ("width_384", {}, 3000, "demos", "policy.dim_model is 256, the row wants 384"),
        ("no_point_maps", {"dim_model": 384}, 3000, "demos", "policy.use_point_map_input is None"),
        ("default", {}, 1500, "demos", "trained for 1500 steps, not --steps 3000"),
        ("default", {}, 3000, "other", "not --data"),
    ],
)
def test_a_checkpoint_trained_otherwise_is_refused(tmp_path, row, policy, steps, root, message):
    ckpt = _checkpoint(tmp_path, steps=steps, root=root, **policy)
    with pytest.raises(SystemExit, match=message):
        check_reused_checkpoint(ckpt, ROWS[row][0], 3000, tmp_path / "demos")


def test_checkpoint_flag_names_a_training_row(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--checkpoint", f"ddim_points={tmp_path}", "--out", str(tmp_path / "a.json")])
    assert "ROW one of the training rows" in capsys.readouterr().err


def test_a_reused_checkpoint_reports_the_command_that_trained_it(tmp_path):
    from benchmarks.run_ablation import reused_train_command

    ckpt = tmp_path / "run" / "train" / "checkpoints" / "003000" / "pretrained_model"
    ckpt.mkdir(parents=True)
    assert reused_train_command(ckpt) is None  # not a harness run: nothing to report
    cmd = ["lerobot-train", "--policy.dim_model=384"]
    (tmp_path / "run" / "run.json").write_text(json.dumps({"commands": {"train": cmd}}))
    assert reused_train_command(ckpt) == cmd


def test_a_row_records_what_its_checkpoint_was_trained_with(tmp_path):
    """The config's defaults change between runs (patch_embed became "conv"), so a row stores the switches read
    back from its checkpoint, not only its overrides."""
    ckpt = _checkpoint(tmp_path, patch_embed="conv", point_update="x0", dim_model=256)
    assert trained_switches(ckpt) == {"patch_embed": "conv", "point_update": "x0", "dim_model": 256, "dropout": 0.0}
    assert trained_switches(tmp_path / "missing") == {}


def test_the_evaluation_env_is_built_with_the_demos_cameras():
    """Demos recorded with other cameras than the env's defaults are evaluated with those cameras (draccus parses
    the flags into the env config that lerobot-eval builds)."""
    import draccus

    from lerobot_rnd.sim.record import recorded_env_args
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig

    settings = {"cameras": ["corner2", "topview"], "flip_cameras": ["corner2"], "image_size": 96,
                "lerobot_corner2_pos": False, "state_layout": "pos_grip_quat_mocap"}  # fmt: skip
    args = [a.removeprefix("--env.") for a in recorded_env_args(settings)]
    cfg = draccus.parse(RnDMetaWorldEnvConfig, args=[f"--{a}" for a in args])
    assert cfg.camera_names == ["corner2", "topview"] and cfg.flip_cameras == ["corner2"]
    assert (cfg.observation_height, cfg.observation_width) == (96, 96)
    assert cfg.use_lerobot_corner2_pos is False and cfg.state_layout == "pos_grip_quat_mocap"
    default = draccus.parse(RnDMetaWorldEnvConfig, args=[
        f"--{a.removeprefix('--env.')}" for a in recorded_env_args({"cameras": ["corner2", "behindGripper"]})])
    assert default.camera_names == ["corner2", "behindGripper"] and default.observation_height == 128


@pytest.mark.parametrize("row", sorted(ROWS))
def test_every_row_switch_is_a_config_field_that_parses(row):
    """A misspelt or out-of-range switch would otherwise surface only after the row's training (an hour): draccus
    parses each row's training and sampler flags into RnDConfig as lerobot-train / lerobot-eval do."""
    import draccus

    from lerobot_rnd.configuration_rnd import RnDConfig

    train_args, _, sampler_args = ROWS[row]
    args = [a.replace("--policy.", "--", 1) for a in (*train_args, *sampler_args)]
    cfg = draccus.parse(RnDConfig, args=args)
    for arg in args:
        key, _, val = arg.removeprefix("--").partition("=")
        assert str(getattr(cfg, key)).lower() == val.lower(), (row, key)


def test_a_misspelt_row_switch_is_refused():
    import draccus

    from lerobot_rnd.configuration_rnd import RnDConfig

    with pytest.raises((SystemExit, draccus.utils.ParsingError, ValueError)):
        draccus.parse(RnDConfig, args=["--n_actions_steps=4"])
