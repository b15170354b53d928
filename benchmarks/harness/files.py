"""JSON files (read tolerant of absence, written atomically) and repository-relative paths."""

from __future__ import annotations

import json
import os
from pathlib import Path

from . import REPO_ROOT


def _read_json(path: Path, default=None):
    try:
        return json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return default


def _write_json(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, default=_json_default))
    os.replace(tmp, path)


def write_result_json(path, payload: dict, argv: list[str] | None = None, script: str | None = None) -> None:
    """A benchmark script's result: ``payload`` plus the ``command`` that made it (``script``, relative to the
    repo, or the process's program, then ``argv`` or the process's arguments), written atomically to ``path``."""
    import sys

    args = argv if argv is not None else sys.argv[1:]
    program = script if script is not None else sys.argv[0]
    _write_json(Path(path), {**payload, "command": "python " + " ".join([program, *args])})
    print(f"wrote {path}")


def _json_default(o):
    if isinstance(o, Path):
        return str(o)
    try:
        import numpy as np

        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(o)}")


def _rel(p: Path) -> str:
    p = Path(p).resolve()
    try:
        return str(p.relative_to(REPO_ROOT))
    except ValueError:
        return str(p)
