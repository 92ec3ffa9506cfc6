"""Writing files so that nothing is ever half written: atomic file and directory writes, and
JSON that is always valid (no NaN or Infinity).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np


def json_safe(value: Any) -> Any:
    """`value` with numpy scalars/arrays as Python values and non-finite floats as None, so
    `json.dumps(..., allow_nan=False)` writes valid JSON (no NaN/Infinity literals)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps_json(value: Any, **kwargs: Any) -> str:
    """json.dumps of `json_safe(value)`: always valid JSON."""
    return json.dumps(json_safe(value), allow_nan=False, **kwargs)


# The signal (SIGINT, SIGTERM) the command line was stopped by, if any: its handler's
# exception can be swallowed by a library (an optional import in a bare `except`), so the
# writers below look here too and write nothing once it is set.
stopped_by: int | None = None


def _stop_if_stopped() -> None:
    if stopped_by is not None:
        raise KeyboardInterrupt


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write a file so that a failure never leaves a half-written one behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        _stop_if_stopped()
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Text version of `atomic_write_bytes` (UTF-8)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def replace_directory(new: Path, target: Path) -> None:
    """Move the directory `new` to `target`, replacing what is there: the old one moves aside
    first and comes back if the move fails (POSIX has no atomic swap of directories)."""
    _stop_if_stopped()
    if not target.exists():
        os.rename(new, target)
        return
    old = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.", suffix=".old"))
    os.rmdir(old)
    os.rename(target, old)
    try:
        os.rename(new, target)
    except BaseException:
        os.rename(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def atomic_directory(
    path: str | os.PathLike, replaceable: Callable[[Path], bool]
) -> Iterator[Path]:
    """Yield an empty temporary sibling of `path`; when the block ends without error, it
    replaces `path`, else it is removed. A non-empty directory already at `path` is
    replaced only if `replaceable(path)` (a mistyped `-o ~` must not delete a home)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"output {path} exists and is not a directory")
    if path.is_dir() and any(path.iterdir()) and not replaceable(path):
        raise ValueError(
            f"output directory {path} is not empty and holds no scanplan output; "
            "choose another or remove it"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private
        replace_directory(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
