"""The shapes the collision checks are made of, as FCL objects: a part's mesh (its BVH built
once while the part lives, shared by the sensor body's checks and the arm's), and the sensor
body, a box in the sensor frame: its corners, and the box rounded by a clearance.
"""

from __future__ import annotations

import weakref

import fcl
import numpy as np

from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.part import Part

# The unit cube's corners, for the body box's 8 corners in the sensor frame.
_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
# Rotations taking a capsule's axis (its z) onto x and onto y.
_TURN_Z_TO_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
_TURN_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def body_corners(sensor: SensorSpec) -> np.ndarray:
    """(8, 3) corners of the sensor body in the sensor frame, mm."""
    lo, hi = sensor.body_bounds_mm
    return lo + _CORNERS * (hi - lo)


def rounded_box(
    half_mm: np.ndarray, clearance_mm: float
) -> list[tuple[fcl.CollisionObject, np.ndarray, np.ndarray]]:
    """The box of half-sizes `half_mm` grown by `clearance_mm` in every direction (a box with
    rounded edges and corners), as the union of three slabs (the box grown along one axis)
    and twelve capsules (its edges grown all round): each piece with its rotation and offset
    from the box's centre, in the box's frame (the sensor frame for the body)."""
    half, c = half_mm, clearance_mm
    pieces: list[tuple[fcl.CollisionObject, np.ndarray, np.ndarray]] = []
    for k in range(3):  # the slabs
        size = 2 * half + 2 * c * np.eye(3)[k]
        pieces.append((fcl.CollisionObject(fcl.Box(*size)), np.eye(3), np.zeros(3)))
    # A capsule lies along its z: turned onto x, y or z, along each of the box's edges.
    turns = (_TURN_Z_TO_X, _TURN_Z_TO_Y, np.eye(3))
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        for si in (-1.0, 1.0):
            for sj in (-1.0, 1.0):
                shift = np.zeros(3)
                shift[i], shift[j] = si * half[i], sj * half[j]
                capsule = fcl.Capsule(c, 2 * half[k])
                pieces.append((fcl.CollisionObject(capsule), turns[k], shift))
    return pieces


_BVHS: weakref.WeakKeyDictionary[Part, fcl.BVHModel] = weakref.WeakKeyDictionary()
_MESH_OBJECTS: weakref.WeakKeyDictionary[Part, fcl.CollisionObject] = weakref.WeakKeyDictionary()


def _mesh_bvh(part: Part) -> fcl.BVHModel:
    """The part's mesh as an FCL BVH, in its own coordinates; built once while the part
    lives (seconds for a large mesh)."""
    if part not in _BVHS:
        _BVHS[part] = triangle_bvh(part.mesh.vertices, part.mesh.faces)
    return _BVHS[part]


def triangle_bvh(vertices: np.ndarray, faces: np.ndarray) -> fcl.BVHModel:
    """An FCL BVH of a triangle mesh, in the coordinates of its vertices."""
    bvh = fcl.BVHModel()
    bvh.beginModel(len(vertices), len(faces))
    bvh.addSubModel(np.asarray(vertices, np.float64), np.asarray(faces, np.int32))
    bvh.endModel()
    return bvh


def mesh_object(part: Part) -> fcl.CollisionObject:
    """The part's mesh as an FCL object in part coordinates, shared by the sensor's and the
    arm's checks, which never move it. A part turned from another (`Part.turned`, a view)
    is that one's BVH, turned."""
    if part not in _MESH_OBJECTS:
        if part.turned_from is not None:
            base, R = part.turned_from
            transform = fcl.Transform(np.asarray(R[:3, :3], np.float64), np.zeros(3))
            _MESH_OBJECTS[part] = fcl.CollisionObject(_mesh_bvh(base), transform)
        else:
            _MESH_OBJECTS[part] = fcl.CollisionObject(_mesh_bvh(part), fcl.Transform())
    return _MESH_OBJECTS[part]


def pieces_touch(
    pieces: list[tuple[fcl.CollisionObject, np.ndarray, np.ndarray]],
    grown: fcl.CollisionObject | None,
    part: fcl.CollisionObject,
    rot: np.ndarray,
    centre: np.ndarray,
) -> np.ndarray:
    """(n,) bool: whether any of `pieces` (`rounded_box`'s, or the box alone) placed at each
    rotation (n, 3, 3) and centre (n, 3) touches `part`. The first piece is tried alone (a
    body in the part meets it at once: one `fcl.collide`); the rest only where `grown`, a
    box holding them all, touches (None: no other piece)."""
    request = fcl.CollisionRequest()
    out = np.zeros(len(rot), bool)
    first, turn, shift = pieces[0]
    for k in range(len(rot)):
        r, c = rot[k], centre[k]
        first.setTransform(fcl.Transform(r @ turn, r @ shift + c))
        if fcl.collide(first, part, request, fcl.CollisionResult()):
            out[k] = True
            continue
        if grown is None:
            continue
        grown.setTransform(fcl.Transform(r, c))
        if not fcl.collide(grown, part, request, fcl.CollisionResult()):
            continue
        for obj, turn_k, shift_k in pieces[1:]:
            obj.setTransform(fcl.Transform(r @ turn_k, r @ shift_k + c))
            if fcl.collide(obj, part, request, fcl.CollisionResult()):
                out[k] = True
                break
    return out
