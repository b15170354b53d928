"""Task conditioning: one R&D policy for several tasks, told apart by LeRobot's `task` string.

A dataset's frames carry a `task` string (`meta/tasks`); `lerobot-eval` passes the environment's task description
the same way. With `task_conditioning`, the dataset's task strings become the policy's vocabulary (`config.tasks`,
saved in config.json) and each maps to a learned embedding that enters the ViT as one token, as the paper's goal
embedding does for its multi-task policy.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import torch
from torch import Tensor

logger = logging.getLogger(__name__)

TASK_KEY = "task"


def dataset_tasks(dataset_meta) -> list[str]:
    """The task strings of a LeRobot dataset, in `task_index` order ([] when it names none)."""
    tasks = getattr(dataset_meta, "tasks", None)
    if tasks is None or len(tasks) == 0:
        return []
    if "task_index" in getattr(tasks, "columns", ()):
        tasks = tasks.sort_values("task_index")
    return [str(t) for t in tasks.index]


def resolve_task_conditioning(config, dataset_meta) -> None:
    """Decide `config.task_conditioning` and fill `config.tasks` when training from scratch on `dataset_meta`.

    None (the default) turns conditioning on when the dataset has several tasks and off for one; it is stated in
    the log. A checkpoint (no `dataset_meta`) keeps what it was trained with.
    """
    if dataset_meta is None:
        if config.task_conditioning and not config.tasks:
            raise ValueError(
                "task_conditioning is on but the config names no tasks: train from a dataset (its meta/tasks gives "
                "the vocabulary) or set --policy.tasks='[\"...\", ...]'."
            )
        return
    tasks = dataset_tasks(dataset_meta)
    if config.task_conditioning is None:
        config.task_conditioning = len(tasks) > 1
    if config.task_conditioning:
        if not tasks:
            raise ValueError(
                "--policy.task_conditioning=true needs the dataset's task strings, but its meta/tasks is empty."
            )
        config.tasks = tasks
        logger.info("R&D task conditioning on: %d task(s) %s, one learned token each", len(tasks), tasks)
    else:
        config.tasks = []
        if len(tasks) > 1:
            logger.warning(
                "R&D task conditioning off although the dataset has %d tasks %s: the policy cannot tell them apart "
                "(--policy.task_conditioning=true to condition on them)", len(tasks), tasks,
            )
        else:
            logger.info("R&D task conditioning off (the dataset has %d task)", len(tasks))


def task_indices(tasks: Sequence[str], batch_tasks, batch_size: int, device) -> Tensor:
    """Indices (B,) long of the batch's task strings in the vocabulary `tasks`.

    `batch_tasks`: the batch's `task` entry (a list of B strings, or one string for all). A missing entry or a task
    outside the vocabulary raises a ValueError naming the known tasks (never a silent default).
    """
    if batch_tasks is None:
        raise ValueError(
            f"This R&D policy was trained on {len(tasks)} tasks {list(tasks)} and needs the observation's "
            f"'{TASK_KEY}' string to know which one to do (lerobot-eval passes the environment's task description; "
            f"in your own loop add batch['{TASK_KEY}'] = [...])."
        )
    if isinstance(batch_tasks, str):
        batch_tasks = [batch_tasks] * batch_size
    batch_tasks = list(batch_tasks)
    if len(batch_tasks) != batch_size:
        raise ValueError(f"'{TASK_KEY}' holds {len(batch_tasks)} strings for a batch of {batch_size}.")
    lookup = {t: i for i, t in enumerate(tasks)}
    unknown = sorted({t for t in batch_tasks if t not in lookup})
    if unknown:
        raise ValueError(
            f"Unknown task(s) {unknown}: this R&D policy knows {list(tasks)} (the tasks of the dataset it was "
            "trained on). Evaluate it on those tasks, or train on a dataset that includes these."
        )
    return torch.tensor([lookup[t] for t in batch_tasks], dtype=torch.long, device=device)
