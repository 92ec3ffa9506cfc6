"""A simulated sensor on a part that does not lie where the CAD says: poses and profiles in
the CAD's frame, the part at `T_part_placed` in it. What a controller in the loop of a
robustness trial measures (`closed_loop.SensorFactory`), and what a policy trained for the
perturbed world (`scanplan train --perturb`) learns from.

Measuring the part in its own frame with the poses moved by the inverse placement is the
same scan; its points and normals are then turned back into the CAD's frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from scanplan.core.sensor_spec import SensorSpec
from scanplan.sensor.profilometer import LineProfilometer, Scan
from scanplan.world.part import Part


class PlacedProfilometer(LineProfilometer):
    """A sensor on `part` lying at `T_part_placed` (4, 4) in the frame the poses are given in:
    poses in, profiles out in that frame (points, normals and poses). The part's ray engine
    is its own (cached on the Part): sensors placed differently on one Part share it."""

    def __init__(
        self, part: Part, spec: SensorSpec, T_part_placed: np.ndarray, seed: int = 0
    ) -> None:
        super().__init__(part, spec, seed)
        self.T_part_placed = np.asarray(T_part_placed, dtype=np.float64)

    def measure_many(self, poses: np.ndarray, rng: np.random.Generator | None = None) -> Scan:
        return measure_placed(self, poses, self.T_part_placed, rng)


def placement(sim: LineProfilometer) -> np.ndarray:
    """(4, 4) where `sim`'s part lies in the frame its poses are given in."""
    return sim.T_part_placed if isinstance(sim, PlacedProfilometer) else np.eye(4)


def measure_placed(
    sim: LineProfilometer,
    poses: np.ndarray,
    T_part_placed: np.ndarray,
    rng: np.random.Generator | None = None,
) -> Scan:
    """Profiles from (m, 4, 4) `poses` of `sim`'s part lying at `T_part_placed`: (4, 4), or
    (m, 4, 4) a placement per pose (several sensors on one part placed differently, measured
    in one call); its own placement, if it has one, is ignored."""
    poses = np.asarray(poses, dtype=np.float64)
    T = np.broadcast_to(np.asarray(T_part_placed, dtype=np.float64), poses.shape)
    if np.array_equal(T, np.broadcast_to(np.eye(4), T.shape)):
        return LineProfilometer.measure_many(sim, poses, rng)
    scan = LineProfilometer.measure_many(sim, np.linalg.inv(T) @ poses, rng)
    # (m, N, 3) points R·p + t and normals R·n, each pose's R and t (one formula for one
    # placement and for many: a batch measures what its sensors would one by one).
    R, t = T[:, None, :3, :3], T[:, None, :3, 3]
    points = (R @ scan.points_part[..., None])[..., 0] + t
    normals = (R @ scan.normals_part[..., None])[..., 0]
    # NaN (no point) stays NaN, a 0 normal (no hit) stays 0.
    return replace(scan, poses=poses, points_part=points, normals_part=normals)


def measure_together(
    sims: Sequence[LineProfilometer], poses: np.ndarray, rng: np.random.Generator | None = None
) -> Scan:
    """Row i of (m, 4, 4) `poses` measured by `sims[i]`, in one call: every sim must be on
    the same Part (placed or not; ValueError otherwise)."""
    part = sims[0].part
    if any(s.part is not part for s in sims):
        raise ValueError("measure_together: the sensors look at different parts")
    if not any(isinstance(s, PlacedProfilometer) for s in sims):
        return sims[0].measure_many(poses, rng)
    return measure_placed(sims[0], poses, np.stack([placement(s) for s in sims]), rng)
