"""Column-first frame queries for LeRobot 0.4.4 image datasets: the same samples, without decoding unused images.

`LeRobotDataset._query_hf_dataset` (LeRobot 0.4.4) reads each delta-timestamp key as
``hf_dataset[key][indices]``. LeRobot sets a custom torch transform on its Hugging Face dataset, and for such
a dataset `datasets` 4.x answers a column query by formatting *every* column of the queried rows. On a dataset
that stores its cameras as images (not videos), one training sample of an 8-step action chunk therefore
decodes 8 x (number of cameras) PNG frames only to read 8 action rows: 30 PNG decodes per R&D sample on a
two-camera MetaWorld dataset, where 6 are needed (and 24 per Diffusion Policy sample with horizon 12).

`install_column_first_queries()` replaces that method with one that selects the key's column before indexing,
so only that column is decoded. The result is the same dict of tensors, element for element
(`tests/test_dataset_query.py` compares both on a recorded dataset and counts the decodes). It is installed by
the plugin shim (`lerobot_policy_rnd`) for `rnd` runs (other policies only with ``LEROBOT_RND_PATCH_ALL=1``;
`lerobot_rnd.plugin_scope`) and by `RnDPolicy` itself, only on the LeRobot version it was checked against, and
never when ``LEROBOT_RND_DATASET_QUERY=upstream`` is set.
"""

from __future__ import annotations

import logging
import os
from importlib import metadata

import torch

CHECKED_LEROBOT_VERSIONS = ("0.4.4",)
OPT_OUT_ENV = "LEROBOT_RND_DATASET_QUERY"  # set to "upstream" to keep LeRobot's own query

_log = logging.getLogger(__name__)


def _column_view(dataset, key: str):
    """`dataset.hf_dataset` restricted to column `key` (same torch transform), cached per Hugging Face dataset
    object: building the view costs about 0.5 ms, a third of reading an 8-row action chunk through it."""
    views = dataset.__dict__.get("_rnd_column_views")
    if views is None or views[0] is not dataset.hf_dataset:
        views = (dataset.hf_dataset, {})
        dataset.__dict__["_rnd_column_views"] = views
    if key not in views[1]:
        views[1][key] = dataset.hf_dataset.select_columns([key])
    return views[1][key]


def query_hf_dataset_column_first(self, query_indices: dict[str, list[int]]) -> dict:
    """`LeRobotDataset._query_hf_dataset`, selecting each key's column before its rows.

    query_indices: {key: absolute frame indices}. Returns {key: (len(indices), ...) stacked tensor}; video
    keys are skipped (LeRobot decodes those by timestamp)."""
    result: dict = {}
    for key, q_idx in query_indices.items():
        if key in self.meta.video_keys:
            continue
        relative_indices = (
            q_idx
            if self._absolute_to_relative_idx is None
            else [self._absolute_to_relative_idx[idx] for idx in q_idx]
        )
        try:
            rows = _column_view(self, key)[relative_indices]
            result[key] = torch.stack(rows[key])
        except (KeyError, TypeError, IndexError, ValueError):  # what upstream falls back to, row first
            result[key] = torch.stack(self.hf_dataset[relative_indices][key])
    return result


def install_column_first_queries() -> bool:
    """Patch `LeRobotDataset._query_hf_dataset` (see the module docstring). Returns whether it is installed."""
    if os.environ.get(OPT_OUT_ENV, "").strip().lower() == "upstream":
        return False
    try:
        version = metadata.version("lerobot")
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
    except (metadata.PackageNotFoundError, ImportError):  # pragma: no cover - lerobot is a dependency
        return False
    if version not in CHECKED_LEROBOT_VERSIONS:
        _log.debug("lerobot %s: keeping its own dataset query (checked: %s)", version, CHECKED_LEROBOT_VERSIONS)
        return False
    if getattr(LeRobotDataset._query_hf_dataset, "__name__", "") != query_hf_dataset_column_first.__name__:
        LeRobotDataset._upstream_query_hf_dataset = LeRobotDataset._query_hf_dataset
        LeRobotDataset._query_hf_dataset = query_hf_dataset_column_first
    return True
