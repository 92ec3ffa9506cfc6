"""Built-in procedural parts (mm, +Z up, footprint centred on the origin, bottom at z = 0).

`build_part(name)` returns a fresh copy of a cached, deterministic watertight mesh.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import trimesh

from . import door, drone, training_piece
from .heightfield import heightfield_solid, ring_solid

__all__ = ["PART_NAMES", "build_part", "heightfield_solid", "ring_solid"]

_BUILDERS: dict[str, Callable[[], trimesh.Trimesh]] = {
    "training-piece": training_piece.build,
    "door": door.build,
    "drone": drone.build,
}
PART_NAMES: tuple[str, ...] = tuple(_BUILDERS)


@cache
def _cached(name: str) -> trimesh.Trimesh:
    return _BUILDERS[name]()


def build_part(name: str) -> trimesh.Trimesh:
    """The built-in part `name` (one of PART_NAMES) as a new mesh in millimetres."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown part {name!r}; built-in parts: {', '.join(PART_NAMES)}")
    return _cached(name).copy()
