"""`lerobot_rnd.dataset_query`: column-first frame queries give LeRobot's own samples with fewer image decodes.

The reference is LeRobot 0.4.4's own `_query_hf_dataset`, run on the same recorded dataset."""

from __future__ import annotations

import json
import subprocess
import sys

import PIL.PngImagePlugin
import pytest
import torch

from lerobot_rnd import dataset_query


@pytest.fixture
def upstream_and_patched():
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    original = LeRobotDataset.__dict__["_query_hf_dataset"]
    upstream = getattr(LeRobotDataset, "_upstream_query_hf_dataset", original)
    yield upstream, dataset_query.query_hf_dataset_column_first
    LeRobotDataset._query_hf_dataset = original


def _dataset(root, obs_steps=2, chunk=8):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    dt = 1.0 / meta.fps
    cams = [k for k in meta.features if k.startswith("observation.images.")]
    delta = {k: [-(obs_steps - 1 - i) * dt for i in range(obs_steps)] for k in [*cams, "observation.state"]}
    delta["action"] = [i * dt for i in range(chunk)]
    return LeRobotDataset("local/toy_reach", root=root, delta_timestamps=delta), cams


def _items_and_decodes(ds, indices, monkeypatch):
    decodes = [0]
    open_png = PIL.PngImagePlugin.PngImageFile._open

    def counting_open(self):
        decodes[0] += 1
        return open_png(self)

    monkeypatch.setattr(PIL.PngImagePlugin.PngImageFile, "_open", counting_open)
    items = [ds[i] for i in indices]
    monkeypatch.setattr(PIL.PngImagePlugin.PngImageFile, "_open", open_png)
    return items, decodes[0]


def test_same_samples_as_lerobot_with_fewer_png_decodes(toy_dataset_root, upstream_and_patched, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    upstream, patched = upstream_and_patched
    ds, cams = _dataset(toy_dataset_root)
    indices = [0, 1, 7, 15, 16, 30, len(ds) - 1]  # episode starts and ends: padded queries too
    LeRobotDataset._query_hf_dataset = upstream
    expected, upstream_decodes = _items_and_decodes(ds, indices, monkeypatch)
    LeRobotDataset._query_hf_dataset = patched
    got, patched_decodes = _items_and_decodes(ds, indices, monkeypatch)

    for want, have in zip(expected, got, strict=True):
        assert want.keys() == have.keys()
        for key, value in want.items():
            if isinstance(value, torch.Tensor):
                assert torch.equal(value, have[key]), key
            else:
                assert value == have[key], key
    # Per sample: the current row's cameras, then 2 history frames per camera; upstream also decodes every
    # camera of the 2 state rows and the 8 action rows.
    n_cams = len(cams)
    assert patched_decodes == len(indices) * (n_cams + 2 * n_cams)
    assert upstream_decodes == len(indices) * (n_cams + 2 * n_cams * n_cams + 2 * n_cams + 8 * n_cams)


def _installed_in_fresh_process(argv: list[str], env: dict | None = None) -> tuple[str, bool]:
    """(module of LeRobotDataset._query_hf_dataset, whether sys.excepthook was replaced) after LeRobot's plugin
    discovery in a fresh process whose command line is `argv`, as lerobot-train runs it."""
    code = (
        "import sys\n"
        f"sys.argv = {argv!r}\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "register_third_party_plugins()\n"
        "from lerobot.datasets.lerobot_dataset import LeRobotDataset\n"
        "print(LeRobotDataset._query_hf_dataset.__module__, sys.excepthook is not sys.__excepthook__)\n"
    )
    import os

    base = {k: v for k, v in os.environ.items() if k not in ("LEROBOT_RND_PATCH_ALL", dataset_query.OPT_OUT_ENV)}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **(env or {})}, capture_output=True, text=True,
                         check=True)  # fmt: skip
    module, hooked = out.stdout.strip().splitlines()[-1].split()
    return module, hooked == "True"


UPSTREAM, PATCHED = "lerobot.datasets.lerobot_dataset", "lerobot_rnd.dataset_query"


def test_an_act_run_with_the_plugin_installed_keeps_lerobots_own_query_and_excepthook():
    act = ["lerobot-train", "--policy.type=act", "--dataset.repo_id=local/x"]
    assert _installed_in_fresh_process(act) == (UPSTREAM, False)
    assert _installed_in_fresh_process(["lerobot-train", "--policy.type", "diffusion"]) == (UPSTREAM, False)
    # opting in applies both to every policy
    assert _installed_in_fresh_process(act, {"LEROBOT_RND_PATCH_ALL": "1"}) == (PATCHED, True)


def test_rnd_runs_get_the_column_first_query_and_can_opt_out(tmp_path):
    assert _installed_in_fresh_process(["lerobot-train", "--policy.type=rnd"]) == (PATCHED, True)
    assert _installed_in_fresh_process(["lerobot-train", "--policy.type", "rnd"]) == (PATCHED, True)
    config = tmp_path / "train.json"
    config.write_text(json.dumps({"policy": {"type": "rnd"}, "steps": 3}))
    assert _installed_in_fresh_process(["lerobot-train", f"--config_path={config}"]) == (PATCHED, True)
    config.write_text(json.dumps({"policy": {"type": "act"}, "steps": 3}))
    assert _installed_in_fresh_process(["lerobot-train", f"--config_path={config}"]) == (UPSTREAM, False)
    (tmp_path / "ckpt").mkdir()
    (tmp_path / "ckpt" / "config.json").write_text(json.dumps({"type": "rnd"}))
    assert _installed_in_fresh_process(["lerobot-eval", f"--policy.path={tmp_path / 'ckpt'}"]) == (PATCHED, True)
    opt_out = {dataset_query.OPT_OUT_ENV: "upstream"}
    assert _installed_in_fresh_process(["lerobot-train", "--policy.type=rnd"], opt_out) == (UPSTREAM, True)


def test_other_lerobot_versions_keep_their_own_query(upstream_and_patched, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    upstream, _ = upstream_and_patched
    LeRobotDataset._query_hf_dataset = upstream
    monkeypatch.delenv(dataset_query.OPT_OUT_ENV, raising=False)
    monkeypatch.setattr(dataset_query.metadata, "version", lambda name: "0.5.0")
    assert dataset_query.install_column_first_queries() is False
    assert LeRobotDataset._query_hf_dataset is upstream


def test_column_views_follow_a_replaced_hf_dataset(toy_dataset_root):
    ds, _ = _dataset(toy_dataset_root)
    first = dataset_query._column_view(ds, "action")
    assert dataset_query._column_view(ds, "action") is first  # cached
    ds.hf_dataset = ds.hf_dataset.select(range(len(ds.hf_dataset)))  # what LeRobot does after adding episodes
    assert dataset_query._column_view(ds, "action") is not first
