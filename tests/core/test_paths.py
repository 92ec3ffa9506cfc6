"""Input files read only if regular: a FIFO, a device, a directory or a broken link is said as
such (never "does not exist", never a read that blocks), by the core readers too."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from scanplan.core.paths import not_regular, read_regular, regular_file
from scanplan.core.plan_file import read_trajectory
from scanplan.core.sensor_files import load_sensor


@pytest.fixture()
def odd_paths(tmp_path) -> dict[str, Path]:
    """One path of each kind that is not a regular file, each named like a data file."""
    paths = {
        "directory": tmp_path / "folder.json",
        "FIFO": tmp_path / "pipe.json",
        "broken link": tmp_path / "broken.json",
        "missing": tmp_path / "missing.json",
    }
    paths["directory"].mkdir()
    os.mkfifo(paths["FIFO"])
    paths["broken link"].symlink_to(tmp_path / "nowhere.json")
    if Path("/dev/zero").exists():
        paths["device link"] = tmp_path / "zero.json"
        paths["device link"].symlink_to("/dev/zero")
    return paths


SAID = {
    "directory": "is a directory, not a file",
    "FIFO": "is a FIFO (named pipe), not a file",
    "broken link": "is a broken link (to ",
    "missing": "does not exist",
    "device link": "is a link to /dev/zero, a character device, not a file",
}


def test_what_a_path_is_in_words(odd_paths, tmp_path):
    for kind, path in odd_paths.items():
        assert SAID[kind] in not_regular(path), kind
        with pytest.raises(ValueError, match=re.escape(f"data file {path} {SAID[kind]}")):
            regular_file(path, "data file")
    plain = tmp_path / "plain.json"
    plain.write_text("{}")
    assert not_regular(plain) is None and regular_file(plain, "data file") == plain
    link = tmp_path / "link.json"
    link.symlink_to(plain)
    assert not_regular(link) is None  # a link to a regular file is one


def test_read_regular_reads_whole_files_under_the_cap(odd_paths, tmp_path):
    plain = tmp_path / "plain.bin"
    plain.write_bytes(b"x" * 100)
    assert read_regular(plain, "data file", 100) == b"x" * 100
    with pytest.raises(ValueError, match=r"data file .*plain.bin is larger than 99 bytes: cut it"):
        read_regular(plain, "data file", 99, "cut it")
    for kind, path in odd_paths.items():  # the FIFO among them: refused, not waited on
        with pytest.raises(ValueError, match=re.escape(SAID[kind])):
            read_regular(path, "data file", 100)


def test_the_core_readers_say_what_the_path_is(odd_paths):
    for kind, path in odd_paths.items():
        with pytest.raises(ValueError, match=re.escape(f"trajectory file {path} {SAID[kind]}")):
            read_trajectory(path)
        sensor = path.with_suffix(".toml")
        if kind != "missing":
            path.rename(sensor)
        if kind == "missing":
            with pytest.raises(ValueError, match="neither a file nor a preset"):
                load_sensor(sensor)
        else:
            with pytest.raises(ValueError, match=re.escape(f"sensor file {sensor} {SAID[kind]}")):
                load_sensor(sensor)
