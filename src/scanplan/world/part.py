"""Parts: load and validate meshes (any unit, any mess real CAD exports come in), in mm.

A `Part` holds the trimesh mesh, a lazily built Embree engine and, optionally, the faces to
inspect (a region of interest, `RegionOfInterest`, SPEC §6). Built-in procedural parts come
from `scanplan.world.parts`.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import math
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import trimesh

from scanplan.core.limits import MAX_TRIANGLES, check_count
from scanplan.world.parts import PART_NAMES, build_part, surface_to_inspect
from scanplan.world.raycast import RayEngine
from scanplan.world.roi import RegionOfInterest, parse_roi

UNITS_TO_MM = {"mm": 1.0, "m": 1000.0, "in": 25.4}
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
STEP_SUFFIXES = (".step", ".stp")
# Parts outside this size (largest extent, mm) are almost surely in the wrong unit.
_MIN_EXTENT_MM, _MAX_EXTENT_MM = 1.0, 20_000.0
# A mesh file larger than this would not fit a planning run in memory: decimate it first.
MAX_MESH_FILE_BYTES = 2 * 1024**3
# STEP tessellation: chord error bounded by the part's size (a fixed 0.01 mm on a 1 m part
# takes >14 GB), angular deflection tight enough for fillets (volume within ~0.05 %).
STEP_MIN_DEFLECTION_MM = 0.01
STEP_RELATIVE_DEFLECTION = 1e-3
STEP_ANGULAR_DEFLECTION_RAD = 0.2


@dataclass(eq=False)
class Part:
    """A part in its own frame, millimetres, +Z up.

    inspect_faces: (f,) bool, the faces of the surface to inspect (a region of interest),
    None = the whole part. Rays always meet the whole mesh: occlusion stays real.
    occluders: meshes in the part's frame that rays meet too (its cell's fixtures, `among`).
    """

    mesh: trimesh.Trimesh
    name: str = "part"
    source: str = ""
    _engine: RayEngine | None = field(default=None, repr=False)
    inspect_faces: np.ndarray | None = field(default=None, repr=False)
    # (the part, R (4, 4)) when this part is that part turned by R (`turned`): its ray
    # engine and collision model are that part's, turned, not built again.
    turned_from: tuple[Part, np.ndarray] | None = field(default=None, repr=False)
    occluders: tuple[trimesh.Trimesh, ...] = field(default=(), repr=False)

    def turned(self, R: np.ndarray) -> Part:
        """This part turned by the rotation R ((4, 4), about the origin; face order and the
        faces to inspect kept). Its ray engine and collision model reuse this part's
        (seconds to build on a mesh of a million faces)."""
        mesh = self.mesh.copy()
        mesh.apply_transform(R)
        base, turn = self, np.asarray(R, dtype=np.float64)
        if self.turned_from is not None:  # turned twice: one turn from the original
            base, first = self.turned_from
            turn = turn @ first
        return Part(
            mesh,
            name=self.name,
            source=self.source,
            inspect_faces=self.inspect_faces,
            turned_from=(base, turn),
            occluders=tuple(m.copy().apply_transform(R) for m in self.occluders),
        )

    def with_roi(self, roi: RegionOfInterest | str | None) -> Part:
        """This part (same mesh and ray engine) restricted to a region of interest; None or
        an empty string: the whole part. Raises ValueError if the ROI selects nothing."""
        if roi is None or (isinstance(roi, str) and not roi.strip()):
            return self
        roi = parse_roi(roi) if isinstance(roi, str) else roi
        mask = roi.face_mask(self.mesh)
        if self.inspect_faces is not None:
            mask &= self.inspect_faces
        if not mask.any():
            raise ValueError(f"--roi {roi.text!r} selects no surface of {self.name}")
        return replace(self, _engine=self.ray_engine, inspect_faces=mask)  # one engine for both

    def among(self, occluders: Sequence[trimesh.Trimesh]) -> Part:
        """This part among other meshes of its frame (its cell's fixtures): its ray engine
        meets them too, so they hide the part from the laser and the camera, and a hit on
        them is no point of it (`RayEngine`). No occluder: this part itself."""
        if not occluders:
            return self
        meshes = self.occluders + tuple(occluders)
        if self.turned_from is not None:  # its engine is another part's: one of its own
            return replace(self, _engine=None, turned_from=None, occluders=meshes)
        engine = self.ray_engine.among([(m.vertices, m.faces) for m in meshes])  # scene shared
        return replace(self, _engine=engine, occluders=meshes)

    @property
    def inspect_mask(self) -> np.ndarray:
        """(f,) bool: the faces to inspect (all of them without a region of interest)."""
        if self.inspect_faces is None:
            return np.ones(len(self.mesh.faces), bool)
        return self.inspect_faces

    @functools.cached_property
    def inspect_vertices(self) -> np.ndarray:
        """(k, 3) the vertices of the faces to inspect: the footprint a raster covers (read
        per pass; a Part's mesh and faces are not changed after it is made)."""
        vertices = np.asarray(self.mesh.vertices)
        if self.inspect_faces is None:
            return vertices
        # A mask, not np.unique: the same vertices in the same order, without the sort.
        used = np.zeros(len(vertices), bool)
        used[np.asarray(self.mesh.faces)[self.inspect_faces].ravel()] = True
        return vertices[used]

    def __getstate__(self) -> dict:
        # Pickled (for another process) without its ray engine, rebuilt there when first used.
        return {**self.__dict__, "_engine": None}

    @property
    def ray_engine(self) -> RayEngine:
        if self._engine is None and self.turned_from is not None:
            base, R = self.turned_from
            self._engine = base.ray_engine.turned(R[:3, :3])
        if self._engine is None:
            occluders = [(m.vertices, m.faces) for m in self.occluders]
            self._engine = RayEngine(self.mesh.vertices, self.mesh.faces, occluders)
        return self._engine

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corners."""
        return np.asarray(self.mesh.bounds)

    @property
    def extents(self) -> np.ndarray:
        return np.asarray(self.mesh.extents)


def validate_mesh(mesh: trimesh.Trimesh, where: str) -> trimesh.Trimesh:
    """Return a cleaned copy, or raise ValueError saying what is wrong with `where`."""
    vertices = np.asarray(mesh.vertices)
    faces = np.asarray(mesh.faces)
    if len(vertices) == 0 or len(faces) == 0:
        raise ValueError(f"mesh {where} is empty (no triangles)")
    if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
        raise ValueError(f"mesh {where}: faces must be triangles of vertex indices")
    out_of_range = (faces < 0) | (faces >= len(vertices))
    if out_of_range.any():
        raise ValueError(
            f"mesh {where}: {int(out_of_range.any(axis=1).sum())} faces reference vertex "
            f"indices outside 0..{len(vertices) - 1} (e.g. {int(faces[out_of_range][0])})"
        )
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise ValueError(f"mesh {where} has {int(bad.sum())} non-finite vertices")
    # Size before any processing: 1e30 coordinates would overflow merge_vertices' rounding.
    used = vertices[np.unique(faces)]
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.max(used.max(axis=0) - used.min(axis=0)))
    if not extent <= _MAX_EXTENT_MM * 10:
        _raise_size(where, extent)
    mesh = mesh.copy()
    mesh.merge_vertices()
    good_faces = mesh.nondegenerate_faces(height=1e-9)
    if not good_faces.any():
        raise ValueError(f"mesh {where} has only degenerate (zero-area) triangles")
    mesh.update_faces(good_faces)
    mesh.remove_unreferenced_vertices()
    extent = float(mesh.extents.max())
    if not _MIN_EXTENT_MM <= extent <= _MAX_EXTENT_MM:
        _raise_size(where, extent)
    return mesh


def _raise_size(where: str, extent: float) -> None:
    raise ValueError(
        f"mesh {where} is {extent:.4g} mm across: outside {_MIN_EXTENT_MM:g}–"
        f"{_MAX_EXTENT_MM:g} mm; check --units (mm|m|in)"
    )


def _decode_text(data: bytes) -> bytes:
    """Text formats as UTF-8: trimesh's own fallback for other encodings needs a package we
    don't ship; Latin-1 maps every byte, so old exporters' comments still load."""
    try:
        data.decode("utf-8")
        return data
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8")


def _binary_stl(data: bytes, path: Path) -> trimesh.Trimesh | None:
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
        raise ValueError(f"part file {path} is not an STL file: {len(data)} bytes, no header")
    raise ValueError(
        f"part file {path} is a corrupt binary STL: its header announces {count} triangles "
        f"({84 + 50 * count} bytes) but the file has {len(data)} bytes"
    )


def _check_glb(data: bytes, path: Path) -> None:
    """The GLB container (magic, declared length, a UTF-8 JSON chunk) before trimesh."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise ValueError(f"part file {path} is not a GLB file (no glTF header)")
    length, chunk_len, chunk_type = np.frombuffer(data, "<u4", 3, 8)
    if length != len(data) or chunk_type != 0x4E4F534A or 20 + chunk_len > len(data):
        raise ValueError(f"part file {path} is a truncated or corrupt GLB file")
    try:
        data[20 : 20 + int(chunk_len)].decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"part file {path}: the GLB's JSON chunk is not UTF-8") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def load_mesh_file(path: str | Path, units: str = "mm") -> trimesh.Trimesh:
    """Read STL/OBJ/PLY/OFF/GLB or STEP; a scene (several bodies) is merged into one mesh.

    `units` scales mesh files; a STEP file carries its own unit and ignores it.
    """
    path = Path(path)
    if units not in UNITS_TO_MM:
        raise ValueError(f"unknown units {units!r}: use one of {', '.join(UNITS_TO_MM)}")
    if path.is_dir():
        raise ValueError(f"part file {path} is a directory, not a mesh file")
    if not path.is_file():
        raise ValueError(f"part file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES + STEP_SUFFIXES:
        formats = ", ".join(MESH_SUFFIXES + STEP_SUFFIXES)
        raise ValueError(f"part file {path}: unsupported format {path.suffix!r} (use {formats})")
    size = path.stat().st_size
    if size == 0:
        raise ValueError(f"part file {path} is empty (0 bytes)")
    if size > MAX_MESH_FILE_BYTES:
        raise ValueError(
            f"part file {path} is {size / 1024**3:.1f} GiB, more than the "
            f"{MAX_MESH_FILE_BYTES / 1024**3:.0f} GiB a part may have: decimate it first"
        )
    try:
        if suffix == ".stl":
            with path.open("rb") as f:
                head = f.read(84)
            count = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
            if 84 + 50 * count == size:  # a binary STL: its triangles counted before reading
                check_count(count, MAX_TRIANGLES, f"part file {path}: triangles", "decimate it")
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"part file {path} cannot be read: {exc.strerror or exc}") from None
    if suffix in STEP_SUFFIXES:
        return _load_step(data, path)
    loaded: object = None
    if suffix == ".stl":
        loaded = _binary_stl(data, path)
    if suffix == ".glb":
        _check_glb(data, path)
    elif suffix in (".stl", ".obj", ".off"):
        data = _decode_text(data)
    if loaded is None:
        try:
            # process=False: merging would silently drop non-finite vertices we must report.
            with np.errstate(all="ignore"):
                # .gltf may refer to buffers beside it: only the path resolves them.
                source = path if suffix == ".gltf" else io.BytesIO(data)
                loaded = trimesh.load(source, file_type=suffix[1:], force="mesh", process=False)
        except Exception as exc:  # trimesh's parsers raise many types on corrupt files
            raise ValueError(
                f"part file {path} cannot be read as {suffix[1:].upper()}: {_first_line(exc)}"
            ) from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"part file {path} holds no triangle mesh")
    loaded.apply_scale(UNITS_TO_MM[units])
    return loaded


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


def _step_to_glb(data: bytes, path: Path, deflection_mm: float) -> trimesh.Trimesh:
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
        raise ValueError(f"part file {path} cannot be read as STEP: {reason}")
    if errors:  # OpenCASCADE skips what it cannot parse and returns the rest: a wrong part
        raise ValueError(
            f"part file {path}: STEP read only in part ({reason}); repair or export it again"
        )
    try:
        with np.errstate(all="ignore"):
            mesh = trimesh.load(io.BytesIO(glb), file_type="glb", force="mesh", process=False)
    except Exception as exc:  # an empty scene, no triangles
        raise ValueError(f"part file {path}: STEP gave no surface ({_first_line(exc)})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"part file {path}: STEP holds no surface to tessellate")
    mesh.apply_scale(1000.0)
    return mesh


# A unit defined by conversion (inch = 25.4 mm): its factor must be a positive length.
_LENGTH_CONVERSION = re.compile(rb"LENGTH_MEASURE_WITH_UNIT\s*\(\s*LENGTH_MEASURE\s*\(([^)]*)\)")


def _check_step_units(data: bytes, path: Path) -> None:
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
                f"part file {path}: STEP length unit converted by {text!r}, not a positive length"
            )


def _load_step(data: bytes, path: Path) -> trimesh.Trimesh:
    """STEP through OpenCASCADE (cascadio): a coarse pass measures the part, the real one
    tessellates with a chord error of max(0.01 mm, 1e-3 x bounding diagonal)."""
    _check_step_units(data, path)
    coarse = _step_to_glb(data, path, deflection_mm=1e9)
    diagonal = float(np.linalg.norm(coarse.extents))
    deflection = max(STEP_MIN_DEFLECTION_MM, STEP_RELATIVE_DEFLECTION * diagonal)
    return _step_to_glb(data, path, deflection_mm=deflection)


@functools.lru_cache(maxsize=8)
def _builtin(name: str) -> Part:
    mesh = validate_mesh(build_part(name), f"built-in {name}")
    return Part(mesh, name=name, source=name, inspect_faces=surface_to_inspect(name, mesh))


def load_part(spec: str | Path, units: str = "mm") -> Part:
    """A built-in part name (see `scanplan.world.parts.PART_NAMES`) or a mesh file path."""
    text = str(spec)
    if units not in UNITS_TO_MM:  # for a built-in part too: a mistake, whatever the part
        raise ValueError(f"unknown units {units!r}: use one of {', '.join(UNITS_TO_MM)}")
    if text in PART_NAMES:
        return _builtin(text)
    path = Path(text)
    if not path.exists() and path.suffix == "":
        raise ValueError(
            f"part {text!r} is neither a file nor a built-in part ({', '.join(PART_NAMES)})"
        )
    mesh = validate_mesh(load_mesh_file(path, units), str(path))
    return Part(mesh, name=path.stem, source=str(path))


def geometry_digest(part: Part) -> str:
    """A short hash of the part's mesh as loaded (vertices in mm to 1e-4, faces): the same
    file in other units, or another file, is another part."""
    mesh = part.mesh
    h = hashlib.sha256(np.round(np.asarray(mesh.vertices, dtype=np.float64), 4).tobytes())
    h.update(np.asarray(mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()[:16]


def part_from_mesh(mesh: trimesh.Trimesh, name: str = "part") -> Part:
    """Wrap an in-memory mesh (mm) after validation."""
    return Part(validate_mesh(mesh, name), name=name, source=name)


# ---- region of interest (SPEC §6) ---------------------------------------------------------
