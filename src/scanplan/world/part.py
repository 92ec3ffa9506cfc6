"""Parts: load (files through `mesh_files`) and validate meshes (any unit, any mess real CAD
exports come in), in mm.

A `Part` holds the trimesh mesh, a lazily built Embree engine and, optionally, the faces to
inspect (a region of interest, `RegionOfInterest`, SPEC §6). Built-in procedural parts come
from `scanplan.world.parts`.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import trimesh

from scanplan.world.mesh_files import UNITS_TO_MM, load_mesh_file
from scanplan.world.parts import PART_NAMES, build_part, surface_to_inspect
from scanplan.world.raycast import RayEngine
from scanplan.world.roi import RegionOfInterest, parse_roi

# Parts outside this size (largest extent, mm) are almost surely in the wrong unit.
_MIN_EXTENT_MM, _MAX_EXTENT_MM = 1.0, 20_000.0


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


@functools.lru_cache(maxsize=8)
def _builtin(name: str) -> Part:
    mesh = validate_mesh(build_part(name), f"built-in {name}")
    return Part(mesh, name=name, source=name, inspect_faces=surface_to_inspect(name, mesh))


def load_part(spec: str | Path, units: str = "mm", what: str = "part file") -> Part:
    """A built-in part name (see `scanplan.world.parts.PART_NAMES`) or a mesh file path;
    `what` names the file in messages ("part file", "fixture file")."""
    text = str(spec)
    if units not in UNITS_TO_MM:  # for a built-in part too: a mistake, whatever the part
        raise ValueError(f"unknown units {units!r}: use one of {', '.join(UNITS_TO_MM)}")
    if text in PART_NAMES:
        return _builtin(text)
    path = Path(text)
    if not path.exists() and not path.is_symlink() and path.suffix == "":
        raise ValueError(
            f"{what.removesuffix(' file')} {text!r} is neither a file nor a built-in part "
            f"({', '.join(PART_NAMES)})"
        )
    mesh = validate_mesh(load_mesh_file(path, units, what), str(path))
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
