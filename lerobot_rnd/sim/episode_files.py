"""A LeRobot dataset that a stopped recorder leaves loadable: each episode's files closed once it is saved, and what
an episode stopped while being saved left behind removed on resume (``lerobot-rnd-record``, docs/FAILURES.md).

LeRobot 0.4.4 keeps an episode's parquet files open, without footer, until ``finalize``; a process killed then
leaves files no reader can open."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

logger = logging.getLogger(__name__)


def discard_unsaved_episode(root: Path) -> int:
    """Remove what a recorder stopped while saving an episode left behind; returns the number of saved episodes.

    The recorder closes an episode's parquet files once it is saved (:func:`close_episode_files`); one
    stopped inside LeRobot's ``save_episode`` can leave parquet files without footer, a data file that no
    episode refers to, and ``meta/info.json`` / ``stats.json`` counting the unsaved episode. Those files are
    removed and the counts and statistics recomputed from ``meta/episodes``, as are the temporary PNGs of an
    episode cut short (``images/``)."""
    import pyarrow.parquet as pq
    from lerobot.datasets.compute_stats import aggregate_stats
    from lerobot.datasets.utils import cast_stats_to_numpy, unflatten_dict, write_stats

    removed = []
    if (root / "images").is_dir():
        shutil.rmtree(root / "images")
        removed.append("images/")
    episode_files = sorted((root / "meta" / "episodes").glob("*/*.parquet"))
    data_files = sorted((root / "data").glob("*/*.parquet"))
    for p in episode_files + data_files:
        try:
            pq.read_metadata(p)
        except Exception:  # noqa: BLE001 - any unreadable file is the unsaved episode's
            p.unlink()
            removed.append(str(p.relative_to(root)))
    episodes = [row for p in episode_files if p.exists() for row in pq.read_table(p).to_pylist()]
    info_path = root / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    referenced = {
        root / info["data_path"].format(chunk_index=e["data/chunk_index"], file_index=e["data/file_index"])
        for e in episodes
    }
    for p in data_files:
        if p.exists() and p not in referenced:
            p.unlink()
            removed.append(str(p.relative_to(root)))
    n, frames = len(episodes), sum(e["length"] for e in episodes)
    if (info["total_episodes"], info["total_frames"]) != (n, frames):
        info.update(total_episodes=n, total_frames=frames, splits={"train": f"0:{n}"})
        info_path.write_text(json.dumps(info, indent=4))
        if n:
            stats = [cast_stats_to_numpy(unflatten_dict({k.removeprefix("stats/"): v for k, v in e.items()
                                                         if k.startswith("stats/")})) for e in episodes]  # fmt: skip
            write_stats(aggregate_stats(stats), root)
        else:
            (root / "meta" / "stats.json").unlink(missing_ok=True)
        removed.append("the unsaved episode from meta/info.json and meta/stats.json")
    if removed:
        logger.warning(f"{root}: removed what an unsaved episode left: {', '.join(removed)}")
    return n


def close_episode_files(dataset) -> None:
    """Close the parquet files of the episode just saved (LeRobot keeps them open, without footer, until
    ``finalize``), so that a killed recorder leaves a loadable dataset. The next episode then goes to new
    files, as after a resume: each episode has its own data and meta/episodes file."""
    import datasets
    from lerobot.datasets.utils import DEFAULT_EPISODES_PATH
    from lerobot.utils.utils import SuppressProgressBars

    dataset.finalize()
    # what LeRobot reads when it resumes (meta.episodes), extended by the episode's row only: reloading all
    # of meta/episodes would cost time in proportion to the episodes recorded, after every episode
    latest = dataset.meta.latest_episode
    path = dataset.root / DEFAULT_EPISODES_PATH.format(
        chunk_index=latest["meta/episodes/chunk_index"][0], file_index=latest["meta/episodes/file_index"][0]
    )
    with SuppressProgressBars():
        row = datasets.Dataset.from_parquet(str(path))
    row = row.select_columns([k for k in row.column_names if not k.startswith("stats/")])
    old = dataset.meta.episodes
    dataset.meta.episodes = row if old is None else datasets.concatenate_datasets([old, row])
    dataset.meta.latest_episode = None  # -> the next episode starts new files after meta.episodes[-1]
    dataset.latest_episode = None
