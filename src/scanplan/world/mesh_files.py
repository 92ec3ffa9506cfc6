"""Mesh files read into trimesh meshes, in mm: STL, OBJ, PLY, OFF, GLB, glTF and STEP (through
OpenCASCADE), with every malformation a one-line ValueError naming the file. A file is read
only if it is a regular one under the size cap, and so is every file a glTF refers to, which
must lie in the glTF's own folder.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import trimesh
from trimesh.resolvers import Resolver

from scanplan.core.limits import MAX_TRIANGLES, check_count
from scanplan.core.paths import not_regular, open_regular, read_regular, regular_file

UNITS_TO_MM = {"mm": 1.0, "m": 1000.0, "in": 25.4}
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
STEP_SUFFIXES = (".step", ".stp")
# A mesh file larger than this would not fit a planning run in memory: decimate it first (a
# glTF and the files it refers to count together).
MAX_MESH_FILE_BYTES = 2 * 1024**3
# STEP tessellation: chord error bounded by the part's size (a fixed 0.01 mm on a 1 m part
# takes >14 GB), angular deflection tight enough for fillets (volume within ~0.05 %).
STEP_MIN_DEFLECTION_MM = 0.01
STEP_RELATIVE_DEFLECTION = 1e-3
STEP_ANGULAR_DEFLECTION_RAD = 0.2


def _decode_text(data: bytes) -> bytes:
    """Text formats as UTF-8: trimesh's own fallback for other encodings needs a package we
    don't ship; Latin-1 maps every byte, so old exporters' comments still load."""
    try:
        data.decode("utf-8")
        return data
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8")


def _binary_stl(data: bytes, where: str) -> trimesh.Trimesh | None:
    """A binary STL read here (header count checked against the size), None if ASCII."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if 84 + 50 * count == len(data):
            record = np.dtype([("normal", "<f4", 3), ("tri", "<f4", (3, 3)), ("attr", "<u2")])
            tris = np.frombuffer(data, record, count, 84)["tri"].astype(np.float64)
            return trimesh.Trimesh(
                tris.reshape(-1, 3), np.arange(3 * count).reshape(-1, 3), process=False
            )
    if data.lstrip()[:5].lower() == b"solid":
        return None
    if len(data) < 84:
        raise ValueError(f"{where} is not an STL file: {len(data)} bytes, no header")
    raise ValueError(
        f"{where} is a corrupt binary STL: its header announces {count} triangles "
        f"({84 + 50 * count} bytes) but the file has {len(data)} bytes"
    )


def _check_glb(data: bytes, where: str) -> None:
    """The GLB container (magic, declared length, a UTF-8 JSON chunk) before trimesh."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise ValueError(f"{where} is not a GLB file (no glTF header)")
    length, chunk_len, chunk_type = np.frombuffer(data, "<u4", 3, 8)
    if length != len(data) or chunk_type != 0x4E4F534A or 20 + chunk_len > len(data):
        raise ValueError(f"{where} is a truncated or corrupt GLB file")
    try:
        data[20 : 20 + int(chunk_len)].decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{where}: the GLB's JSON chunk is not UTF-8") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def load_mesh_file(path: str | Path, units: str = "mm", what: str = "part file") -> trimesh.Trimesh:
    """Read STL/OBJ/PLY/OFF/GLB/glTF or STEP; a scene (several bodies) is merged into one
    mesh. `units` scales mesh files; a STEP file carries its own unit and ignores it. `what`
    names the file in messages ("part file", "fixture file")."""
    path = Path(path)
    where = f"{what} {path}"
    if units not in UNITS_TO_MM:
        raise ValueError(f"unknown units {units!r}: use one of {', '.join(UNITS_TO_MM)}")
    regular_file(path, what)  # a FIFO would block the read, a link to /dev/zero never end
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES + STEP_SUFFIXES:
        formats = ", ".join(MESH_SUFFIXES + STEP_SUFFIXES)
        raise ValueError(f"{where}: unsupported format {path.suffix!r} (use {formats})")
    data = _read(path, what, suffix)
    if suffix in STEP_SUFFIXES:
        return _load_step(data, where)
    loaded: object = None
    if suffix == ".stl":
        loaded = _binary_stl(data, where)
    if suffix == ".glb":
        _check_glb(data, where)
    elif suffix in (".stl", ".obj", ".off"):
        data = _decode_text(data)
    if loaded is None:
        loaded = _parsed(data, suffix, path, where)
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"{where} holds no triangle mesh")
    loaded.apply_scale(UNITS_TO_MM[units])
    return loaded


def _read(path: Path, what: str, suffix: str) -> bytes:
    """The file's bytes, its size (and a binary STL's triangles) checked before reading."""
    where = f"{what} {path}"
    with open_regular(path, what) as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise ValueError(f"{where} is empty (0 bytes)")
        if size > MAX_MESH_FILE_BYTES:
            raise ValueError(
                f"{where} is {size / 1024**3:.1f} GiB, more than the "
                f"{MAX_MESH_FILE_BYTES / 1024**3:.0f} GiB a part may have: decimate it first"
            )
        try:
            if suffix == ".stl":
                head = f.read(84)
                count = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
                if 84 + 50 * count == size:  # a binary STL: its triangles counted first
                    check_count(count, MAX_TRIANGLES, f"{where}: triangles", "decimate it")
                f.seek(0)
            return f.read(MAX_MESH_FILE_BYTES)
        except OSError as exc:
            raise ValueError(f"{where} cannot be read: {exc.strerror or exc}") from None


def _parsed(data: bytes, suffix: str, path: Path, where: str) -> object:
    """trimesh's reading of a mesh file's bytes (a .gltf's files read by `_FolderFiles`)."""
    resolver = _FolderFiles(path, where, MAX_MESH_FILE_BYTES - len(data))
    try:
        # process=False: merging would silently drop non-finite vertices we must report.
        with np.errstate(all="ignore"):
            return trimesh.load(
                io.BytesIO(data),
                file_type=suffix[1:],
                force="mesh",
                process=False,
                resolver=resolver if suffix == ".gltf" else None,
            )
    except _Refused as exc:
        raise ValueError(str(exc)) from None
    except Exception as exc:  # trimesh's parsers raise many types on corrupt files
        raise ValueError(
            f"{where} cannot be read as {suffix[1:].upper()}: {_first_line(exc)}"
        ) from None


class _Refused(ValueError):
    """A file a glTF refers to that is not read (outside its folder, not a regular file,
    over the size cap): said as is, not as a parse error."""


class _FolderFiles(Resolver):
    """The files a glTF refers to (buffers, images): only regular files inside the glTF's
    own folder (after links), together under `budget` bytes. trimesh's own resolver opens
    whatever the name leads to: a FIFO there blocks the load until killed."""

    def __init__(self, gltf: Path, where: str, budget: int) -> None:
        self.folder = gltf.parent.resolve()
        self.where = where
        self.budget = budget

    def get(self, name: str) -> bytes:
        path = self.folder / name.strip()
        problem = not_regular(path)
        if problem is not None:
            raise _Refused(f"{self.where} refers to {name!r}, which {problem}")
        target = path.resolve()
        if not target.is_relative_to(self.folder):
            raise _Refused(f"{self.where} refers to {name!r}, outside its folder {self.folder}")
        what = f"{self.where} refers to {name!r}:"
        try:
            data = read_regular(target, what, max(self.budget, 0), "decimate the part")
        except ValueError as exc:
            raise _Refused(str(exc)) from None
        self.budget -= len(data)
        return data

    def write(self, name: str, data: str | bytes) -> None:
        raise _Refused(f"{self.where}: nothing is written beside a part")

    def keys(self) -> Iterator[str]:
        return iter(())

    def namespaced(self, namespace: str) -> Resolver:
        raise _Refused(f"{self.where}: refers to the folder {namespace!r}")


@contextlib.contextmanager
def _captured_fds() -> Iterator[Callable[[], str]]:
    """Capture what C++ code prints on file descriptors 1 and 2 (OpenCASCADE reports parse
    errors there), so a bad file gives one line instead of a screenful."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    sink = tempfile.TemporaryFile()
    try:
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)

        def text() -> str:
            sink.seek(0)
            return sink.read().decode("utf-8", "replace")

        yield text
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
        sink.close()


def _step_to_glb(data: bytes, where: str, deflection_mm: float) -> trimesh.Trimesh:
    import cascadio

    with _captured_fds() as printed:
        # cascadio tessellates in OpenCASCADE's session unit (mm) and writes metres.
        glb = cascadio.load(
            data,
            file_type="step",
            tol_linear=deflection_mm,
            tol_angular=STEP_ANGULAR_DEFLECTION_RAD,
            merge_primitives=True,
        )
        log = printed()
    errors = [ln for ln in re.sub(r"\x1b\[[0-9;]*m", "", log).splitlines() if "ERR" in ln]
    reason = errors[0].strip(" *").split(":", 2)[-1].strip() if errors else "no shape in it"
    if not glb:
        raise ValueError(f"{where} cannot be read as STEP: {reason}")
    if errors:  # OpenCASCADE skips what it cannot parse and returns the rest: a wrong part
        raise ValueError(f"{where}: STEP read only in part ({reason}); repair or export it again")
    try:
        with np.errstate(all="ignore"):
            mesh = trimesh.load(io.BytesIO(glb), file_type="glb", force="mesh", process=False)
    except Exception as exc:  # an empty scene, no triangles
        raise ValueError(f"{where}: STEP gave no surface ({_first_line(exc)})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{where}: STEP holds no surface to tessellate")
    mesh.apply_scale(1000.0)
    return mesh


# A unit defined by conversion (inch = 25.4 mm): its factor must be a positive length.
_LENGTH_CONVERSION = re.compile(rb"LENGTH_MEASURE_WITH_UNIT\s*\(\s*LENGTH_MEASURE\s*\(([^)]*)\)")


def _check_step_units(data: bytes, where: str) -> None:
    """A length unit converted by a factor <= 0 (or not a number) would mirror or collapse
    the part; OpenCASCADE applies it without a word."""
    for match in _LENGTH_CONVERSION.finditer(data):
        text = match.group(1).decode("ascii", "replace").strip()
        try:
            factor = float(text)
        except ValueError:
            factor = float("nan")
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(
                f"{where}: STEP length unit converted by {text!r}, not a positive length"
            )


def _load_step(data: bytes, where: str) -> trimesh.Trimesh:
    """STEP through OpenCASCADE (cascadio): a coarse pass measures the part, the real one
    tessellates with a chord error of max(0.01 mm, 1e-3 x bounding diagonal)."""
    _check_step_units(data, where)
    coarse = _step_to_glb(data, where, deflection_mm=1e9)
    diagonal = float(np.linalg.norm(coarse.extents))
    deflection = max(STEP_MIN_DEFLECTION_MM, STEP_RELATIVE_DEFLECTION * diagonal)
    return _step_to_glb(data, where, deflection_mm=deflection)
