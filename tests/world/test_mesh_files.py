"""Mesh files read only if regular, and the files a glTF refers to only if regular, inside its
folder and under the size cap: a FIFO for a buffer is refused at once, never read."""

from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import numpy as np
import pytest
import trimesh

import scanplan.world.mesh_files as mesh_files
from scanplan.world.part import load_part


@pytest.fixture()
def gltf(tmp_path) -> Path:
    """A 20 mm box as a .gltf with its two buffers beside it (gltf_buffer_0.bin, _1.bin)."""
    folder = tmp_path / "box"
    folder.mkdir()
    trimesh.creation.box((20.0, 20.0, 20.0)).export(folder / "box.gltf")
    assert {p.name for p in folder.iterdir()} == {
        "box.gltf",
        "gltf_buffer_0.bin",
        "gltf_buffer_1.bin",
    }
    return folder / "box.gltf"


@contextmanager
def unblocked(fifo: Path, after_s: float = 10.0) -> Iterator[None]:
    """If a reader still waits on `fifo` after `after_s`, a writer opens and closes it (the
    reader gets end of file), so that a regression fails the test instead of hanging it."""
    done = threading.Event()

    def writer() -> None:
        if not done.wait(after_s):
            with suppress(OSError):  # ENXIO: nobody reads it after all
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))

    thread = threading.Thread(target=writer, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def test_a_gltf_loads_as_trimesh_loads_it(gltf):
    part = load_part(gltf)
    expected = trimesh.load(gltf, force="mesh", process=False)
    assert len(part.mesh.faces) == 12
    np.testing.assert_allclose(part.mesh.bounds, expected.bounds)


def test_a_gltf_buffer_that_is_a_fifo_is_refused_at_once(gltf):
    fifo = gltf.parent / "gltf_buffer_1.bin"
    fifo.unlink()
    os.mkfifo(fifo)
    start = time.monotonic()
    with unblocked(fifo), pytest.raises(ValueError) as err:
        load_part(gltf)
    assert time.monotonic() - start < 5.0
    assert str(err.value) == (
        f"part file {gltf} refers to 'gltf_buffer_1.bin', which is a FIFO (named pipe), not a file"
    )


@pytest.mark.parametrize(
    ("uri", "message"),
    [
        ("../outside.bin", r"refers to '../outside.bin', outside its folder"),
        ("/etc/hostname", r"refers to '/etc/hostname', outside its folder"),
        ("zero.bin", r"refers to 'zero.bin', which is a link to /dev/zero, a character device"),
        ("sub", r"refers to 'sub', which is a directory, not a file"),
        ("gone.bin", r"refers to 'gone.bin', which does not exist"),
    ],
)
def test_a_gltf_refers_only_to_regular_files_in_its_folder(gltf, uri, message):
    folder = gltf.parent
    (folder.parent / "outside.bin").write_bytes((folder / "gltf_buffer_0.bin").read_bytes())
    (folder / "zero.bin").symlink_to("/dev/zero")
    (folder / "sub").mkdir()
    text = gltf.read_text().replace('"uri":"gltf_buffer_0.bin"', f'"uri":"{uri}"')
    assert uri in text
    gltf.write_text(text)
    with pytest.raises(ValueError, match=f"^part file {re.escape(str(gltf))} {message}"):
        load_part(gltf)


def test_a_gltf_and_its_buffers_count_together_against_the_cap(gltf, monkeypatch):
    sizes = [gltf.stat().st_size, *(p.stat().st_size for p in gltf.parent.glob("*.bin"))]
    monkeypatch.setattr(mesh_files, "MAX_MESH_FILE_BYTES", sum(sizes) - 1)
    with pytest.raises(ValueError, match=r"refers to 'gltf_buffer_\d.bin': .* is larger than"):
        load_part(gltf)
    monkeypatch.setattr(mesh_files, "MAX_MESH_FILE_BYTES", sum(sizes))
    assert len(load_part(gltf).mesh.faces) == 12


def test_a_part_or_fixture_file_that_is_not_a_file_is_said_so(tmp_path):
    fifo = tmp_path / "part.stl"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match=f"^part file {fifo} is a FIFO"):
        load_part(fifo)
    with pytest.raises(ValueError, match=f"^fixture file {tmp_path} is a directory, not a file"):
        load_part(tmp_path, what="fixture file")
    with pytest.raises(ValueError, match="^fixture '.*clamp' is neither a file nor a built-in"):
        load_part(tmp_path / "clamp", what="fixture file")
