"""Input files read only if they are regular files, and what a path is when it is not: a
FIFO blocks the read until killed, a device (a link to /dev/zero) never ends, and "does not
exist" misleads a user whose path names a directory.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

# What a stat's file type is, in words.
_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def not_regular(path: str | os.PathLike) -> str | None:
    """What `path` is when it is not a regular file (after links), in words ("does not
    exist", "is a directory", "is a link to /dev/zero, a character device", ...); None for a
    regular file."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        if path.is_symlink():
            return f"is a broken link (to {os.readlink(path)})"
        return "does not exist"
    except NotADirectoryError:
        return "does not exist (a folder on its way is a file)"
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    if stat.S_ISREG(mode):
        return None
    if path.is_symlink():
        return f"is a link to {path.resolve()}, {_kind(mode)}, not a file"
    return f"is {_kind(mode)}, not a file"


def regular_file(path: str | os.PathLike, what: str) -> Path:
    """`path` if it names a regular file (after links), else a ValueError saying what it is:
    "`what` PATH is a FIFO (named pipe), not a file"."""
    problem = not_regular(path)
    if problem is not None:
        raise ValueError(f"{what} {os.fspath(path)} {problem}")
    return Path(path)


@contextmanager
def open_regular(path: str | os.PathLike, what: str) -> Iterator[BinaryIO]:
    """The regular file `path` open for reading, else a ValueError naming `what` and the
    path. Opened without blocking and checked on the open file: a path swapped for a FIFO
    after a check still cannot hang the read."""
    regular_file(path, what)
    name = os.fspath(path)
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise ValueError(f"{what} {name} cannot be read: {exc.strerror or exc}") from None
    with open(fd, "rb") as f:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise ValueError(f"{what} {name} is {_kind(mode)}, not a file")
        yield f


def read_regular(path: str | os.PathLike, what: str, max_bytes: int, hint: str = "") -> bytes:
    """The bytes of the regular file `path`, at most `max_bytes` (`hint` says what to do
    about a larger one), else a ValueError naming `what` and the path (`open_regular`)."""
    with open_regular(path, what) as f:
        try:
            data = f.read(max_bytes + 1)
        except OSError as exc:
            name = os.fspath(path)
            raise ValueError(f"{what} {name} cannot be read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        more = f": {hint}" if hint else ""
        raise ValueError(f"{what} {os.fspath(path)} is larger than {_size(max_bytes)}{more}")
    return data


def _size(n: int) -> str:
    """A byte count as a message shows it (1 MiB, 2 GiB, 300 bytes)."""
    for unit, factor in (("GiB", 1024**3), ("MiB", 1024**2), ("KiB", 1024)):
        if n >= factor:
            return f"{n / factor:g} {unit}"
    return f"{n} bytes"
