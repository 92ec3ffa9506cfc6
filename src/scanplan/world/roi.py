"""The region of interest: the `--roi` grammar (boxes, normal cones, bodies, joined by ';')
and the faces of a mesh it selects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

ROI_HELP = (
    "region of interest, terms joined by ';' (AND): box:x0,y0,z0,x1,y1,z1 (mm, part frame: "
    "faces whose centroid lies inside), +z:30 (faces whose normal is within 30 deg of +Z; "
    "any of +x -x +y -y +z -z, or n:X,Y,Z:DEG), body:I (the I-th connected body, from 0, in "
    "trimesh's mesh.split(only_watertight=False) order)"
)


_AXES = {
    f"{sign}{name}": np.array([float(sign + "1") if i == k else 0.0 for k in range(3)])
    for sign in "+-"
    for i, name in enumerate("xyz")
}


@dataclass(frozen=True)
class BoxTerm:
    """Faces whose centroid lies in the axis-aligned box [lo, hi] (part frame, mm)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def face_mask(self, mesh: trimesh.Trimesh) -> np.ndarray:
        c = np.asarray(mesh.triangles_center)
        return np.all((c >= np.array(self.lo)) & (c <= np.array(self.hi)), axis=1)


@dataclass(frozen=True)
class ConeTerm:
    """Faces whose normal is within `angle_rad` of `axis` (unit). A mesh whose winding is not
    consistent has no trustworthy normal sign: there either sign of the normal counts."""

    axis: tuple[float, float, float]
    angle_rad: float

    def face_mask(self, mesh: trimesh.Trimesh) -> np.ndarray:
        cos = np.asarray(mesh.face_normals) @ np.array(self.axis)
        if not mesh.is_winding_consistent:
            cos = np.abs(cos)
        return cos >= math.cos(self.angle_rad) - 1e-12


@dataclass(frozen=True)
class BodyTerm:
    """The faces of the `index`-th connected body (face adjacency), in the order of trimesh's
    `mesh.split(only_watertight=False)`: a STEP file's solids, a multi-shell STL's shells."""

    index: int

    def face_mask(self, mesh: trimesh.Trimesh) -> np.ndarray:
        bodies = mesh_bodies(mesh)
        if self.index >= len(bodies):
            raise ValueError(
                f"--roi body:{self.index}: the part has {len(bodies)} bodies (0..{len(bodies) - 1})"
            )
        mask = np.zeros(len(mesh.faces), bool)
        mask[bodies[self.index]] = True
        return mask


def mesh_bodies(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Face indices of each connected body, in `mesh.split(only_watertight=False)`'s order."""
    return list(
        trimesh.graph.connected_components(
            edges=mesh.face_adjacency, nodes=np.arange(len(mesh.faces)), min_len=1
        )
    )


RoiTerm = BoxTerm | ConeTerm | BodyTerm


@dataclass(frozen=True)
class RegionOfInterest:
    """The surface a user wants inspected: the faces every term selects (AND). `text` is the
    --roi string it was parsed from (for messages)."""

    terms: tuple[RoiTerm, ...]
    text: str = ""

    def face_mask(self, mesh: trimesh.Trimesh) -> np.ndarray:
        """(f,) bool over `mesh.faces`."""
        mask = np.ones(len(mesh.faces), bool)
        for term in self.terms:
            mask &= term.face_mask(mesh)
        return mask


def _numbers(text: str, count: int, what: str, roi: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ValueError(f"--roi {roi!r}: {what}")
    return values


def _parse_term(term: str, roi: str) -> RoiTerm:
    key, _, rest = term.partition(":")
    key = key.strip().lower()
    if key == "box":
        v = _numbers(rest, 6, "box takes x0,y0,z0,x1,y1,z1 in mm", roi)
        lo, hi = np.minimum(v[:3], v[3:]), np.maximum(v[:3], v[3:])
        return BoxTerm(
            (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))
        )
    if key == "body":
        if not rest.strip().isdigit():
            raise ValueError(f"--roi {roi!r}: body takes a body index 0, 1, ...")
        return BodyTerm(int(rest))
    if key in _AXES or key == "n":
        if key == "n":
            vec, _, deg = rest.rpartition(":")
            axis = np.array(_numbers(vec, 3, "a normal cone is n:X,Y,Z:DEG", roi))
        else:
            axis, deg = _AXES[key], rest
        angle = _numbers(deg, 1, "a normal cone needs an angle in degrees, e.g. +z:30", roi)[0]
        norm = float(np.linalg.norm(axis))
        if norm < 1e-12 or not 0.0 <= angle <= 180.0:
            raise ValueError(f"--roi {roi!r}: a cone needs a non-zero axis and 0 <= DEG <= 180")
        a = axis / norm
        return ConeTerm((float(a[0]), float(a[1]), float(a[2])), math.radians(angle))
    raise ValueError(
        f"--roi {roi!r}: unknown term {term.strip()!r} (use box:..., +z:DEG, n:X,Y,Z:DEG, body:I)"
    )


def parse_roi(text: str) -> RegionOfInterest:
    """The --roi string as a `RegionOfInterest` (see `ROI_HELP`); ValueError naming --roi."""
    terms = [t for t in text.split(";") if t.strip()]
    if not terms:
        raise ValueError(f"--roi {text!r}: empty region of interest")
    return RegionOfInterest(tuple(_parse_term(t, text) for t in terms), text)
