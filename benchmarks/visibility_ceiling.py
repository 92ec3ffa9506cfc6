"""The most of a part's upper-hemisphere surface any scan could hold in spec: the share of
its samples (`surface.hemisphere_visible_samples`) that some beam within the angle
tolerance of the normal, and no more than `surface.VIEW_AXIS_MAX_TILT_DEG` (or 90°) from +Z,
reaches without hitting the part (`surface.reachable_samples`, which `evaluate` reports as
`visibility_ceiling`). A bound, not a plan: it ignores the depth window, the
sensor body and tracking, so real plans stay below it. The last column also asks for the
camera's line of sight, as the simulator does: a triangulation sensor sees a point only if
its camera, at the triangulation angle from the beam (on any side: the sensor may turn
about its beam), sees it too, from in front of the face.

    PYTHONPATH=src python benchmarks/visibility_ceiling.py [PARTS_DIR] [--beams 24]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from compare_views import PARTS  # the shared parts and their units (benchmarks/)

from scanplan.core.quantities import ScanSpec
from scanplan.world.part import load_part
from scanplan.world.surface import (
    VIEW_AXIS_MAX_TILT_DEG,
    hemisphere_visible_samples,
    oriented_normals,
    reachable_samples,
    unit_perpendicular,
)


def ceiling(
    part,
    tol_rad: float,
    max_tilt_deg: float,
    beams: int,
    seed: int = 0,
    camera_rad: float | None = None,
    camera_sides: int = 8,
) -> float:
    """The share of the samples some beam reaches (see the module); with `camera_rad`, the
    camera at that angle from the beam must see the point too (`camera_sides` azimuths)."""
    surface = hemisphere_visible_samples(part, 3.0, seed)
    also = None
    if camera_rad is not None:
        n = oriented_normals(part)[surface.faces]

        def also(todo, start, beam):
            return _camera_sees(part, start, n[todo], beam, camera_rad, camera_sides)

    seen = reachable_samples(part, surface, tol_rad, max_tilt_deg, beams, seed, also)
    return float(seen.mean()) if len(seen) else 0.0


def _camera_sees(part, start, n, beam, camera_rad: float, sides: int) -> np.ndarray:
    """(k,) bool: a camera `camera_rad` from the beam, on one of `sides` azimuths about it,
    is in front of the face and sees the point unobstructed."""
    first = unit_perpendicular(beam, np.random.default_rng(1))
    second = np.cross(beam, first)
    sees = np.zeros(len(beam), bool)
    for k in range(sides):
        az = 2 * math.pi * k / sides
        look = math.cos(camera_rad) * beam + math.sin(camera_rad) * (
            math.cos(az) * first + math.sin(az) * second
        )
        todo = np.flatnonzero(~sees & (np.sum(look * n, axis=1) > 0))
        if len(todo):
            far = np.full(len(todo), 1e6)
            sees[todo] = ~part.ray_engine.occluded(start[todo], look[todo], far)
    return sees


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--beams", type=int, default=24)
    args = ap.parse_args()
    tol = ScanSpec().tol_angle_rad
    camera = ScanSpec().sensor.triangulation_angle_rad
    print(
        f"part | ceiling, axis <= {VIEW_AXIS_MAX_TILT_DEG:g}° | ceiling, axis <= 90° | "
        f"with the camera, axis <= {VIEW_AXIS_MAX_TILT_DEG:g}°"
    )
    for name, units in PARTS.items():
        part = load_part(Path(args.parts_dir) / name, units)
        low = ceiling(part, tol, VIEW_AXIS_MAX_TILT_DEG, args.beams)
        high = ceiling(part, tol, 90.0, args.beams)
        seen = ceiling(part, tol, VIEW_AXIS_MAX_TILT_DEG, args.beams, camera_rad=camera)
        print(f"{name} | {low:.3f} | {high:.3f} | {seen:.3f}", flush=True)


if __name__ == "__main__":
    main()
