"""The ready configs in policies_config/ parse as lerobot-train configs and build valid policy configs."""

from pathlib import Path

import draccus
import pytest

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "policies_config").glob("**/*.json"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_config_parses_as_a_train_config(path):
    import lerobot.policies  # noqa: F401  (registers ACT and Diffusion Policy)
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_rnd  # noqa: F401  (registers rnd)
    import lerobot_rnd.sim  # noqa: F401  (registers rnd_mw; the core does not import the simulators)

    cfg = draccus.parse(TrainPipelineConfig, str(path), args=[])
    assert cfg.policy is not None and cfg.policy.type in {"rnd", "act", "diffusion"}
    # the folder names the suite: metaworld/ -> rnd_mw, panda/ -> rnd_panda (7-D actions, 8-D state), so101/ ->
    # rnd_so101 (LeRobot's 6 SO-101 joints as state and action)
    want = {"metaworld": "rnd_mw", "panda": "rnd_panda", "so101": "rnd_so101"}[path.parent.name]
    assert cfg.env is not None and cfg.env.type == want
    if want == "rnd_panda":
        assert cfg.env.action_dim == 7 and cfg.env.state_dim() == 8
        assert cfg.env.features["action"].shape == (7,)
    if want == "rnd_so101":
        assert cfg.env.action_dim == 6 and cfg.env.state_dim() == 6 and cfg.env.fps == 30
    assert cfg.policy.push_to_hub is False
    if cfg.policy.type == "rnd":
        assert cfg.policy.n_obs_steps == 2 and cfg.policy.chunk_size == 8
    if cfg.policy.type == "act":
        assert cfg.policy.pretrained_backbone_weights is None  # no downloads offline


def test_inference_benchmark_times_the_cpu_tier_that_training_builds():
    """bench_inference's "cpu" R&D is the model that `lerobot-train --config_path=rnd_ai_cpu.json` builds (it once
    kept a hand copy that missed patch_embed=conv and timed the old model)."""
    import sys

    import lerobot.policies  # noqa: F401
    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_rnd  # noqa: F401
    import lerobot_rnd.sim  # noqa: F401
    from lerobot_rnd.configuration_rnd import RnDConfig

    repo = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(repo / "benchmarks"))
    try:
        import bench_inference
    finally:
        sys.path.remove(str(repo / "benchmarks"))
    trained = draccus.parse(TrainPipelineConfig, str(repo / "policies_config/metaworld/rnd_ai_cpu.json"), args=[]).policy
    timed = RnDConfig(**bench_inference.RND_CONFIGS["cpu"])
    skip = {"device", "push_to_hub", "input_features", "output_features", "normalization_mapping"}
    fields = [f for f in RnDConfig.__dataclass_fields__ if f not in skip]
    def norm(v):
        return tuple(norm(x) for x in v) if isinstance(v, (list, tuple)) else v

    differ = {f: (getattr(timed, f), getattr(trained, f)) for f in fields
              if norm(getattr(timed, f)) != norm(getattr(trained, f))}  # fmt: skip
    assert not differ
    assert trained.patch_embed == "conv" and trained.dim_model != RnDConfig().dim_model  # not the paper defaults


@pytest.mark.parametrize("suite", ["panda", "so101"])
def test_suite_cpu_configs_mirror_the_metaworld_cpu_configs(suite):
    """policies_config/<suite>/*_cpu.json are the MetaWorld CPU configs (same model sizes and training settings) with
    the suite's dataset and env: the benchmark compares the suites at one model size. The one exception is the Panda
    R&D's 16-px patches (its cube is 10-16 px wide; policies_config/README.md says why)."""
    import json

    exceptions = {("panda", "rnd_ai_cpu.json"): {"patch_size": 16}}

    root = Path(__file__).resolve().parents[1] / "policies_config"
    names = sorted(p.name for p in (root / suite).glob("*.json"))
    assert names == ["act_cpu.json", "diffusion_cpu.json", "rnd_ai_cpu.json"]
    for name in names:
        mw, panda = (json.loads((root / d / name).read_text()) for d in ("metaworld", suite))
        assert panda["policy"] == {**mw["policy"], **exceptions.get((suite, name), {})}, name
        assert panda["env"]["type"] == f"rnd_{suite}" and panda["dataset"]["root"].startswith(f"data/{suite}_")
        assert {k: v for k, v in panda.items() if k not in ("env", "dataset", "policy")} == \
            {k: v for k, v in mw.items() if k not in ("env", "dataset", "policy")}  # fmt: skip


def test_train_step_benchmark_takes_each_suites_config_and_dataset(tmp_path):
    """bench_train_step's `so101/act_cpu` is policies_config/so101/act_cpu.json on the so101 dataset, a bare name
    MetaWorld's on its own (issue 34's cost question compares the suites in one run)."""
    import sys

    repo = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(repo / "benchmarks"))
    try:
        import bench_train_step as bench
    finally:
        sys.path.remove(str(repo / "benchmarks"))
    roots = bench.dataset_roots([f"metaworld={tmp_path / 'mw'}", f"so101={tmp_path / 'arm'}"])
    assert roots == {"metaworld": str(tmp_path / "mw"), "so101": str(tmp_path / "arm")}
    assert bench.dataset_roots(["data/x"]) == {"*": "data/x"}
    so101 = bench.load_train_config("so101/act_cpu", roots["so101"], 4)
    assert so101.env.type == "rnd_so101" and so101.policy.type == "act" and so101.batch_size == 4
    assert Path(so101.dataset.root) == tmp_path / "arm" and so101.dataset.repo_id == "local/arm"
    mw = bench.load_train_config("act_cpu", roots["metaworld"], 8)
    assert mw.env.type != "rnd_so101" and Path(mw.dataset.root) == tmp_path / "mw"
    with pytest.raises(FileNotFoundError, match="policies_config/SUITE/NAME"):
        bench.load_train_config("so101/no_such_config", roots["so101"], 8)
