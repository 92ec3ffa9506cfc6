"""Writing files (files.py): atomic writes leave no temporary and a readable file, and on a
full disk the previous file or folder and one line naming the output; a device or FIFO is
written into, never replaced (a link to one too); the JSON writer's values are always valid
JSON (no NaN or Infinity), numpy included."""

from __future__ import annotations

import errno
import json
import math
import os
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given

from helpers import FAST, JSON_VALUES, ROOT, full_disk, listing
from scanplan.core.files import (
    atomic_directory,
    atomic_write_bytes,
    atomic_write_text,
    dumps_json,
    output_kind,
)


def test_atomic_write_leaves_no_temporary_and_a_readable_file(tmp_path):

    from scanplan.core.files import atomic_write_text

    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "out.txt", "hello\n")
    finally:
        os.umask(old)
    assert (tmp_path / "out.txt").read_text() == "hello\n"
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o644  # not mkstemp's 0600
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


@FAST
@given(value=JSON_VALUES)
def test_json_safe_always_gives_valid_json(value):
    text = dumps_json(value)

    def refuse(literal: str) -> None:
        raise AssertionError(f"{literal} in {text}")

    json.loads(text, parse_constant=refuse)  # no NaN/Infinity literal anywhere


def test_json_safe_on_numpy():
    out = json.loads(dumps_json({"a": np.array([1.0, np.nan]), "b": np.int64(3), "c": math.inf}))
    assert out == {"a": [1.0, None], "b": 3, "c": None}


# ---- outputs that are no regular file, and writes that fail ---------------------------------
def test_a_full_disk_leaves_the_previous_file_and_no_temporary(tmp_path, monkeypatch):
    out = tmp_path / "out.csv"
    out.write_text("previous\n")
    full_disk(monkeypatch)
    with pytest.raises(OSError) as caught:
        atomic_write_text(out, "new\n")
    assert caught.value.errno == errno.ENOSPC
    assert str(caught.value) == f"[Errno 28] cannot write {out}: No space left on device"
    assert caught.value.strerror == f"cannot write {out}: No space left on device"
    assert out.read_text() == "previous\n" and listing(tmp_path) == ["out.csv"]


def test_a_failed_folder_leaves_the_previous_one_and_names_the_output(tmp_path, monkeypatch):
    out = tmp_path / "report"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    full_disk(monkeypatch, fail_at=2)
    with pytest.raises(OSError) as caught:
        with atomic_directory(out, lambda p: True) as tmp:
            atomic_write_text(tmp / "a.txt", "new a")
            atomic_write_text(tmp / "b.txt", "new b")
    assert caught.value.errno == errno.ENOSPC
    assert caught.value.strerror == f"cannot write {out / 'b.txt'}: No space left on device"
    assert listing(tmp_path) == ["report"] and listing(out) == ["a.txt"]
    assert (out / "a.txt").read_text() == "old a"
    monkeypatch.undo()  # room again
    with pytest.raises(KeyboardInterrupt), atomic_directory(out, lambda p: True) as tmp:
        atomic_write_text(tmp / "a.txt", "new a")
        raise KeyboardInterrupt  # Ctrl-C halfway
    assert listing(tmp_path) == ["report"] and (out / "a.txt").read_text() == "old a"


def test_a_fifo_is_written_into_when_read_and_refused_when_not(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    start = time.monotonic()
    with pytest.raises(ValueError, match=f"output {fifo} is a FIFO that nobody reads"):
        atomic_write_text(fifo, "lost\n")
    assert time.monotonic() - start < 1.0
    read: list[bytes] = []
    reader = threading.Thread(target=lambda: read.append(fifo.read_bytes()))
    reader.start()
    deadline = time.monotonic() + 5
    while True:  # the reader opens its end as its thread starts
        try:
            atomic_write_text(fifo, "through the pipe\n")
            break
        except ValueError:
            assert time.monotonic() < deadline
            time.sleep(0.01)
    reader.join(5)
    assert read == [b"through the pipe\n"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and listing(tmp_path) == ["pipe"]
    with pytest.raises(ValueError, match="exists and is not a directory: it is a FIFO"):
        with atomic_directory(fifo, lambda p: True):
            pass


def test_a_link_to_a_device_is_written_into_never_replaced(tmp_path):
    for device in ("/dev/null", "/dev/full"):
        if not Path(device).exists():
            pytest.skip(f"no {device}")
        link = tmp_path / Path(device).name
        link.symlink_to(device)
        # Proven before any write: the writer opens a character device, it never renames.
        assert output_kind(link) == "character device"
    before = os.stat("/dev/null")
    atomic_write_text(tmp_path / "null", "gone\n")
    with pytest.raises(OSError) as caught:
        atomic_write_text(tmp_path / "full", "too much\n")
    assert caught.value.errno == errno.ENOSPC and "cannot write" in str(caught.value)
    for name in ("null", "full"):
        assert os.readlink(tmp_path / name) == f"/dev/{name}"
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev
    assert listing(tmp_path) == ["full", "null"]


def test_a_link_to_a_file_replaces_the_file_and_keeps_the_link(tmp_path):
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "out.csv"
    target.write_text("old\n")
    link = tmp_path / "out.csv"
    link.symlink_to(target)
    atomic_write_text(link, "new\n")
    assert link.is_symlink() and target.read_text() == "new\n"
    assert listing(tmp_path / "real") == ["out.csv"]


def test_a_socket_is_refused(tmp_path):
    path = tmp_path / "sock"
    with socket.socket(socket.AF_UNIX) as server:
        server.bind(str(path))
        with pytest.raises(ValueError, match=f"output {path} is a socket; not writing to it"):
            atomic_write_bytes(path, b"x")
    assert stat.S_ISSOCK(os.lstat(path).st_mode)


def test_standard_output_is_written_through_in_order_and_not_replaced(tmp_path):
    # `-o /dev/stdout > out.txt`: the shell holds out.txt open; replacing it would lose
    # what is printed after, and a pipe or terminal must be written into.
    code = (
        "import sys; from scanplan.core.files import atomic_write_text; "
        "print('before'); atomic_write_text(sys.argv[1], 'the output\\n'); print('after')"
    )
    out = tmp_path / "out.txt"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    for name in ("/dev/stdout", str(out)):
        with out.open("w") as f:
            inode = os.fstat(f.fileno()).st_ino
            subprocess.run([sys.executable, "-c", code, name], stdout=f, env=env, check=True)
        assert out.read_text() == "before\nthe output\nafter\n", name
        assert out.stat().st_ino == inode and listing(tmp_path) == ["out.txt"]
    piped = subprocess.run(
        [sys.executable, "-c", code, "/dev/stdout"], capture_output=True, env=env, check=True
    )
    assert piped.stdout == b"before\nthe output\nafter\n"
