"""Built-in procedural parts (mm, +Z up, footprint centred on the origin, bottom at z = 0).

`build_part(name)` returns a fresh copy of a cached, deterministic watertight mesh;
`surface_to_inspect(name, mesh)` the faces inspected on it (None: all of them).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import numpy as np
import trimesh

from . import door, drone, training_piece
from .heightfield import heightfield_solid, ring_solid

__all__ = ["PART_NAMES", "build_part", "heightfield_solid", "ring_solid", "surface_to_inspect"]

_BUILDERS: dict[str, Callable[[], trimesh.Trimesh]] = {
    "training-piece": training_piece.build,
    "door": door.build,
    "drone": drone.build,
}
PART_NAMES: tuple[str, ...] = tuple(_BUILDERS)
# Parts whose solid only closes a sheet: what is inspected is the sheet (its skin).
_SKINS: dict[str, Callable[[trimesh.Trimesh], np.ndarray]] = {"door": door.skin_faces}


@cache
def _cached(name: str) -> trimesh.Trimesh:
    return _BUILDERS[name]()


def build_part(name: str) -> trimesh.Trimesh:
    """The built-in part `name` (one of PART_NAMES) as a new mesh in millimetres."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown part {name!r}; built-in parts: {', '.join(PART_NAMES)}")
    return _cached(name).copy()


def surface_to_inspect(name: str, mesh: trimesh.Trimesh) -> np.ndarray | None:
    """(f,) bool: the faces of built-in part `name` to inspect (its skin), or None: all."""
    skin = _SKINS.get(name)
    return None if skin is None else skin(mesh)
