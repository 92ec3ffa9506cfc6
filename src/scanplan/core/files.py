"""Writing files so that nothing is ever half written: atomic file and directory writes, and
JSON that is always valid (no NaN or Infinity).
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import stat
import sys
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


def output_kind(path: str | os.PathLike) -> str | None:
    """What `path` names when it is neither a regular file nor a directory (following
    links): "character device", "FIFO", "block device", "socket"; None otherwise (nothing
    there, a dangling link, a regular file, a directory)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    for test, kind in (
        (stat.S_ISCHR, "character device"),
        (stat.S_ISFIFO, "FIFO"),
        (stat.S_ISBLK, "block device"),
        (stat.S_ISSOCK, "socket"),
    ):
        if test(mode):
            return kind
    return None


def _write_into(path: Path, data: bytes, kind: str) -> None:
    """Write `data` into the device or FIFO `path` (opened, never replaced): a FIFO must have
    a reader already (else the write would wait for one forever)."""
    flags = os.O_WRONLY | os.O_TRUNC | (os.O_NONBLOCK if kind == "FIFO" else 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if exc.errno == errno.ENXIO and kind == "FIFO":
            raise ValueError(
                f"output {path} is a FIFO that nobody reads; not writing to it"
            ) from None
        raise cannot_write(path, exc) from None
    try:
        os.set_blocking(fd, True)
        with os.fdopen(fd, "wb", closefd=False) as f:
            f.write(data)
    except OSError as exc:
        raise cannot_write(path, exc) from None
    finally:
        os.close(fd)


def _own_stream(path: Path) -> int | None:
    """1 or 2 when `path` is this process's standard output or error (`-o /dev/stdout`, or
    the file the shell redirected it to), else None."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    for fd in (1, 2):
        try:
            own = os.fstat(fd)
        except OSError:
            continue
        if (own.st_dev, own.st_ino) == (st.st_dev, st.st_ino):
            return fd
    return None


def _write_stream(fd: int, path: Path, data: bytes) -> None:
    """Write `data` through the standard stream `fd` itself, after what was printed to it:
    in order with the printed lines, and not replacing the file the shell holds open."""
    (sys.stdout if fd == 1 else sys.stderr).flush()
    view = memoryview(data)
    try:
        while view:
            view = view[os.write(fd, view) :]
    except OSError as exc:
        raise cannot_write(path, exc) from None


def cannot_write(path: str | os.PathLike, exc: OSError) -> OSError:
    """`exc` as one line naming the output (not its temporary stand-in); errno kept, so a
    full disk is still an OSError of ENOSPC."""
    text = f"cannot write {path}: {exc.strerror or exc}"
    return OSError(text) if exc.errno is None else OSError(exc.errno, text)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write a file so that a failure never leaves a half-written one behind: a temporary
    file beside it renamed over it. This process's standard output or error (`-o
    /dev/stdout`) is written through it; a character device or FIFO (a link to /dev/null) is
    written into, never replaced; a block device or socket is refused; a link to a regular
    file replaces the file it names, not the link."""
    path = Path(path)
    stream = _own_stream(path)
    if stream is not None:
        _stop_if_stopped()
        _write_stream(stream, path, data)
        return
    kind = output_kind(path)
    if kind in ("character device", "FIFO"):
        _stop_if_stopped()
        _write_into(path, data, kind)
        return
    if kind is not None:
        raise ValueError(f"output {path} is a {kind}; not writing to it")
    if path.is_symlink():
        target = _link_target(path)
        if path.exists() and not (target.exists() and os.path.samefile(target, path)):
            # A link the kernel makes (/dev/stdout of a deleted file): no path to replace.
            _write_into(path, data, "file")
            return
        path = target
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        _stop_if_stopped()
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise cannot_write(path, exc) from None
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise


def _link_target(link: Path) -> Path:
    """The path a symbolic link names, resolved (the file to replace, so the link stays)."""
    return Path(os.path.realpath(link))


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
    replaced only if `replaceable(path)` (a mistyped `-o ~` must not delete a home); a link
    to a directory replaces the directory it names, not the link. A write that fails names
    the file as it would be in `path`, not in the temporary."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        kind = output_kind(path) or "file"
        raise ValueError(f"output {path} exists and is not a directory: it is a {kind}")
    if path.is_symlink():
        path = _link_target(path)
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
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _renamed(exc, tmp, path) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _renamed(exc: OSError, tmp: Path, path: Path) -> OSError:
    """`exc` with the temporary directory `tmp` in its message and file name read as `path`
    (the output the user named); the same error otherwise."""
    text, name = str(exc.strerror or exc), exc.filename
    if str(tmp) not in text and str(tmp) not in str(name or ""):
        return exc
    text = text.replace(str(tmp), str(path))
    if exc.errno is None:
        return OSError(text)
    return OSError(
        exc.errno, text, None if name is None else str(name).replace(str(tmp), str(path))
    )
