"""Surface defects, seeded, injected into a part's mesh: dent and bump (a smooth bell of a
depth and a diameter), pit (a small steep-walled crater) and scratch (a narrow groove of a
width, depth and length along a direction in the surface).

A defect is a displacement of the surface along its outward normal with compact support: the
faces within reach are halved until their edges are shorter than the defect's resolution
(`resolution_mm`), then the vertices in reach move. Vertices beyond the support stay put, so
the T-junctions at the refined region's border lie on straight, undisplaced edges: no crack.
Everything here is arrays and a seed: the same (seed, index) always draws the same defects.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
import trimesh

Size = TypeVar("Size", float, np.ndarray)  # one defect size, or one per sample

KINDS = ("dent", "bump", "pit", "scratch")
# Width (diameter; a scratch's width) over depth when a defect is sized by its depth alone
# (`shape`): a dent is shallow and wide, a pit a small crater, a scratch a narrow groove
# `SCRATCH_LENGTH` widths long.
ASPECT = {"dent": 10.0, "bump": 10.0, "pit": 4.0, "scratch": 4.0}
SCRATCH_LENGTH = 10.0
# The finest edge the refinement makes, mm, and the edges per defect width it aims at.
MIN_EDGE_MM = 0.03
EDGES_PER_WIDTH = 10.0
# A vertex farther than this share of the support off the defect's tangent plane is another
# side of the part (the back of a sheet): never moved.
TANGENT_SLAB = 0.25


@dataclass(frozen=True)
class Defect:
    """One defect: `kind`; centre_mm (3,) on the nominal surface; normal (3,) the outward
    unit normal there; direction (3,) a unit tangent (a scratch's length runs along it);
    depth_mm > 0 (a bump's height); width_mm the diameter (a scratch's width); length_mm a
    scratch's length (0 otherwise)."""

    kind: str
    centre_mm: np.ndarray
    normal: np.ndarray
    direction: np.ndarray
    depth_mm: float
    width_mm: float
    length_mm: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown defect type {self.kind!r}; use {', '.join(KINDS)}")
        if not (self.depth_mm > 0 and self.width_mm > 0 and self.length_mm >= 0):
            raise ValueError(f"{self.kind}: depth and width must be > 0")

    @property
    def radius_mm(self) -> float:
        """The support's reach from the centre: beyond it the surface is nominal."""
        return max(self.width_mm, self.length_mm) / 2

    @property
    def resolution_mm(self) -> float:
        return max(MIN_EDGE_MM, self.width_mm / EDGES_PER_WIDTH)

    @property
    def size_mm(self) -> float:
        """The size a POD curve is drawn against: the depth (a bump's height)."""
        return self.depth_mm

    def displacement_mm(self, points: np.ndarray) -> np.ndarray:
        """(k,) the displacement along `normal` at (k, 3) points (negative: into the part)."""
        rel = points - self.centre_mm
        height = rel @ self.normal
        tangent = rel - height[:, None] * self.normal
        r_half = self.width_mm / 2
        if self.kind == "scratch":
            along = np.abs(tangent @ self.direction)
            across = np.linalg.norm(
                tangent - (tangent @ self.direction)[:, None] * self.direction, axis=1
            )
            u = np.clip(across / r_half, 0.0, 1.0)
            profile = (1.0 - u**2) ** 2  # a rounded groove
            # Its ends taper over half a width to nothing at length / 2.
            end = np.clip((self.length_mm / 2 - along) / r_half, 0.0, 1.0)
            profile = profile * end * end * (3.0 - 2.0 * end)
        else:
            u = np.clip(np.linalg.norm(tangent, axis=1) / r_half, 0.0, 1.0)
            if self.kind == "pit":
                profile = (1.0 - u**6) ** 2  # flat floor, steep wall
            else:
                profile = (1.0 - u**2) ** 3  # a smooth bell, C2 at its rim
        profile = np.where(np.abs(height) <= TANGENT_SLAB * max(self.radius_mm, 1.0), profile, 0.0)
        sign = 1.0 if self.kind == "bump" else -1.0
        return sign * self.depth_mm * profile

    def to_json_dict(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "centre_mm": [round(float(v), 3) for v in self.centre_mm],
            "depth_mm": self.depth_mm,
            "width_mm": self.width_mm,
            "length_mm": self.length_mm,
        }


def shape(kind: str, size_mm: Size) -> tuple[Size, Size, Size]:
    """(depth, width, length) mm of a `kind` defect of size (depth) `size_mm`, by `ASPECT`;
    element-wise for an array of sizes."""
    if kind not in KINDS:
        raise ValueError(f"unknown defect type {kind!r}; use {', '.join(KINDS)}")
    width = ASPECT[kind] * size_mm
    return size_mm, width, (SCRATCH_LENGTH if kind == "scratch" else 0.0) * width


def place(
    kind: str,
    sizes_mm: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    rng: np.random.Generator,
    gap_mm: float,
) -> list[Defect]:
    """One defect of each size (`shape`) at a random one of the (k, 3) candidate `points`
    (outward unit `normals`), no two centres closer than `gap_mm` plus their reaches; a size
    for which no such place is left is dropped. The scratch's direction is random in the
    tangent plane."""
    placed: list[Defect] = []
    centres = np.zeros((0, 3))
    reaches = np.zeros(0)
    order = rng.permutation(len(points))
    cursor = 0
    for size in sizes_mm:
        depth, width, length = shape(kind, float(size))
        reach = max(width, length) / 2
        while cursor < len(order):
            i = order[cursor]
            cursor += 1
            d = np.linalg.norm(centres - points[i], axis=1)
            if np.all(d >= gap_mm + reach + reaches):
                break
        else:
            break
        n = normals[i] / np.linalg.norm(normals[i])
        t = np.cross(n, rng.normal(size=3))
        t /= max(float(np.linalg.norm(t)), 1e-12)
        placed.append(Defect(kind, points[i].copy(), n, t, depth, width, length))
        centres = np.vstack([centres, points[i]])
        reaches = np.append(reaches, reach)
    return placed


def inject(
    mesh: trimesh.Trimesh, defects: list[Defect], max_faces: int = 4_000_000
) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The mesh with `defects` in it, and (f',) the index of the original face each new
    face came from (so a region of interest carries over). Raises ValueError when refining
    would pass `max_faces`."""
    vertices = np.asarray(mesh.vertices, np.float64)
    faces = np.asarray(mesh.faces, np.int64)
    origin = np.arange(len(faces))
    if not defects:
        return trimesh.Trimesh(vertices, faces, process=False), origin
    # Only faces that reach a defect are ever refined (their children reach it or not): the
    # rest of a large mesh is looked at once.
    near = _reaching(vertices[faces], defects, 0.0)
    for _ in range(60):
        candidates = np.flatnonzero(near)
        tri = vertices[faces[candidates]]
        todo = candidates[_reaching(tri, defects, 1.0)]
        if len(todo) == 0:
            break
        if len(faces) + 3 * len(todo) > max_faces:
            raise ValueError(
                f"defects too large for this mesh: refining them passes {max_faces:,} faces"
            )
        vertices, new_faces = trimesh.remesh.subdivide(vertices, faces, face_index=todo)
        # trimesh puts the untouched faces first, then the four children of each refined one.
        keep = np.ones(len(faces), bool)
        keep[todo] = False
        origin = np.concatenate([origin[keep], np.repeat(origin[todo], 4)])
        near = np.concatenate([near[keep], np.ones(4 * len(todo), bool)])
        faces = np.asarray(new_faces, np.int64)
    vertices = vertices.copy()
    for defect in defects:
        near = np.linalg.norm(vertices - defect.centre_mm, axis=1) < defect.radius_mm
        vertices[near] += defect.displacement_mm(vertices[near])[:, None] * defect.normal
    return trimesh.Trimesh(vertices, faces, process=False), origin


def _reaching(tri: np.ndarray, defects: list[Defect], coarse: float) -> np.ndarray:
    """(f,) bool: which (f, 3, 3) triangles may come within a defect's reach (and, with
    `coarse` 1, still have an edge longer than its resolution)."""
    centroid = tri.mean(axis=1)
    spread = np.sqrt(((tri - centroid[:, None]) ** 2).sum(axis=2).max(axis=1))
    edge = np.sqrt(((tri - np.roll(tri, 1, axis=1)) ** 2).sum(axis=2).max(axis=1))
    out = np.zeros(len(tri), bool)
    for d in defects:
        rel = centroid - d.centre_mm
        reach = d.radius_mm
        if d.kind == "scratch":  # the groove's strip, not the disc its length spans
            along = np.clip(rel @ d.direction, -d.length_mm / 2, d.length_mm / 2)
            rel = rel - along[:, None] * d.direction
            reach = d.width_mm / 2
        dist = np.sqrt((rel**2).sum(axis=1))
        out |= (dist < reach + spread) & (edge > coarse * d.resolution_mm)
    return out


def with_size(defect: Defect, size_mm: float) -> Defect:
    """The same defect at the same place, sized `size_mm` (`shape`)."""
    depth, width, length = shape(defect.kind, size_mm)
    return replace(defect, depth_mm=depth, width_mm=width, length_mm=length)
