"""A view's sensor poses moved as a whole, each about what it measures: beams turned towards
straight down about their footprints (a wall's view kept above the table; raised for an
arm), and lines slid along themselves (an arm reaching the near end of each line).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.world.surface import VIEW_AXIS_MAX_TILT_DEG


def limit_beam_tilt(
    poses: np.ndarray, up: np.ndarray, pivot_mm: float, max_tilt_deg: float = VIEW_AXIS_MAX_TILT_DEG
) -> np.ndarray:
    """(n, 4, 4) `poses` whose beam (z_s) leans more than `max_tilt_deg` from straight down
    (−`up`, the table's normal) turned back to that tilt about the point `pivot_mm` along the
    beam (the footprint at W_d). A planner aligning the beam with a vertical wall would lay
    the sensor level with the wall's foot, the table there; at the view's tilt the wall is
    still within 10° of the beam, inside the angle tolerance."""
    down = -np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    tilt = np.arccos(np.clip(poses[:, :3, 2] @ down, -1.0, 1.0))
    return _turned_down(poses, down, pivot_mm, tilt - math.radians(max_tilt_deg))


def raised_beams(poses: np.ndarray, pivot_mm: float, deg: float) -> np.ndarray:
    """(n, 4, 4) `poses` with each beam (z_s) raised by `deg` towards straight down (−Z)
    about the point `pivot_mm` along it (the footprint at W_d), a beam nearer than that to
    straight down turned onto it: the same footprints, seen from higher up, within the
    angle tolerance when `deg` is."""
    down = np.array([0.0, 0.0, -1.0])
    tilt = np.arccos(np.clip(poses[:, :3, 2] @ down, -1.0, 1.0))
    return _turned_down(poses, down, pivot_mm, np.minimum(tilt, math.radians(deg)))


def _turned_down(
    poses: np.ndarray, down: np.ndarray, pivot_mm: float, angle: np.ndarray
) -> np.ndarray:
    """`poses` each turned by its `angle` (rad; none where <= 0) towards `down` about the
    point `pivot_mm` along its beam."""
    turn = np.flatnonzero(angle > 1e-9)
    if len(turn) == 0:
        return poses
    out = poses.copy()
    beam = poses[turn, :3, 2]
    axis = np.cross(beam, down)
    norm = np.linalg.norm(axis, axis=1, keepdims=True)
    axis = np.where(norm > 1e-9, axis / np.maximum(norm, 1e-12), [1.0, 0.0, 0.0])
    rot = Rotation.from_rotvec(axis * angle[turn, None]).as_matrix()
    footprint = poses[turn, :3, 3] + pivot_mm * beam
    out[turn, :3, :3] = rot @ poses[turn, :3, :3]
    out[turn, :3, 3] = footprint - pivot_mm * out[turn, :3, 2]
    return out


def slid_lines(poses: np.ndarray, swath: np.ndarray, towards: np.ndarray, mm: float) -> np.ndarray:
    """(n, 4, 4) `poses` each moved `mm` along its laser line (x_s), every pose of a pass
    (`swath`) the way that brings the pass nearer the point `towards` (3,) on the whole: the
    beams and the line keep their directions, so each line measures what lay `mm` nearer
    its far end, and the sensor comes that much nearer an arm standing there."""
    line = poses[:, :3, 0]
    way = np.einsum("ij,ij->i", line, np.asarray(towards) - poses[:, :3, 3])
    passes, at = np.unique(swath, return_inverse=True)
    sign = np.sign(np.bincount(at, way, len(passes)))[at]
    out = poses.copy()
    out[:, :3, 3] += (mm * sign)[:, None] * line
    return out
