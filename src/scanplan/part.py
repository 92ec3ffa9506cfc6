"""Parts: load and validate meshes (any unit, any mess real CAD exports come in), in mm.

A `Part` holds the trimesh mesh and a lazily built Embree engine. Built-in procedural parts
come from `scanplan.parts`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from scanplan.raycast import RayEngine

UNITS_TO_MM = {"mm": 1.0, "m": 1000.0, "in": 25.4}
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
# Parts outside this size (largest extent, mm) are almost surely in the wrong unit.
_MIN_EXTENT_MM, _MAX_EXTENT_MM = 1.0, 20_000.0


@dataclass(eq=False)
class Part:
    """A part in its own frame, millimetres, +Z up."""

    mesh: trimesh.Trimesh
    name: str = "part"
    source: str = ""
    _engine: RayEngine | None = field(default=None, repr=False)

    @property
    def ray_engine(self) -> RayEngine:
        if self._engine is None:
            self._engine = RayEngine(self.mesh.vertices, self.mesh.faces)
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
    if len(mesh.vertices) == 0 or len(mesh.faces) == 0:
        raise ValueError(f"mesh {where} is empty (no triangles)")
    bad = ~np.isfinite(mesh.vertices).all(axis=1)
    if bad.any():
        raise ValueError(f"mesh {where} has {int(bad.sum())} non-finite vertices")
    mesh = mesh.copy()
    mesh.merge_vertices()
    good_faces = mesh.nondegenerate_faces(height=1e-9)
    if not good_faces.any():
        raise ValueError(f"mesh {where} has only degenerate (zero-area) triangles")
    mesh.update_faces(good_faces)
    mesh.remove_unreferenced_vertices()
    extent = float(mesh.extents.max())
    if not _MIN_EXTENT_MM <= extent <= _MAX_EXTENT_MM:
        raise ValueError(
            f"mesh {where} is {extent:.4g} mm across: outside {_MIN_EXTENT_MM:g}–"
            f"{_MAX_EXTENT_MM:g} mm; check --units (mm|m|in)"
        )
    return mesh


def load_mesh_file(path: str | Path, units: str = "mm") -> trimesh.Trimesh:
    """Read STL/OBJ/PLY/OFF/GLB; a scene (several bodies) is merged into one mesh."""
    path = Path(path)
    if units not in UNITS_TO_MM:
        raise ValueError(f"unknown units {units!r}: use one of {', '.join(UNITS_TO_MM)}")
    if path.is_dir():
        raise ValueError(f"part file {path} is a directory, not a mesh file")
    if not path.is_file():
        raise ValueError(f"part file {path} does not exist")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(
            f"part file {path}: unsupported format {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})"
        )
    try:
        # process=False: merging would silently drop non-finite vertices we must report.
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on corrupt files
        raise ValueError(f"part file {path} cannot be read as a mesh: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"part file {path} holds no triangle mesh")
    loaded.apply_scale(UNITS_TO_MM[units])
    return loaded


@functools.lru_cache(maxsize=8)
def _builtin(name: str) -> Part:
    from scanplan.parts import build_part

    return Part(validate_mesh(build_part(name), f"built-in {name}"), name=name, source=name)


def load_part(spec: str | Path, units: str = "mm") -> Part:
    """A built-in part name (see `scanplan.parts.PART_NAMES`) or a mesh file path."""
    from scanplan.parts import PART_NAMES

    text = str(spec)
    if text in PART_NAMES:
        return _builtin(text)
    path = Path(text)
    if not path.exists() and path.suffix == "":
        raise ValueError(
            f"part {text!r} is neither a file nor a built-in part ({', '.join(PART_NAMES)})"
        )
    mesh = validate_mesh(load_mesh_file(path, units), str(path))
    return Part(mesh, name=path.stem, source=str(path))


def part_from_mesh(mesh: trimesh.Trimesh, name: str = "part") -> Part:
    """Wrap an in-memory mesh (mm) after validation."""
    return Part(validate_mesh(mesh, name), name=name, source=name)
