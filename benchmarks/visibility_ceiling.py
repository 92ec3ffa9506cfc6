"""The most of a part's upper-hemisphere surface any scan could hold in spec: the share of
its samples (`metrics.hemisphere_visible_samples`) that some beam within the angle
tolerance of the normal, and no more than `views.VIEW_AXIS_MAX_TILT_DEG` (or 90°) from +Z,
reaches without hitting the part. A bound, not a plan: it ignores the depth window, the
camera's own line of sight and tracking, so real plans stay below it.

    PYTHONPATH=src python benchmarks/visibility_ceiling.py [PARTS_DIR] [--beams 24]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from compare_views import PARTS  # the shared parts and their units (benchmarks/)

from scanplan.metrics import hemisphere_visible_samples
from scanplan.part import load_part
from scanplan.quantities import ScanSpec
from scanplan.views import VIEW_AXIS_MAX_TILT_DEG, oriented_normals


def ceiling(part, tol_rad: float, max_tilt_deg: float, beams: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    surface = hemisphere_visible_samples(part, 3.0, seed)
    n = oriented_normals(part)[surface.faces]
    seen = np.zeros(len(n), bool)
    lowest = math.cos(math.radians(max_tilt_deg)) - 1e-9
    for k in range(beams):
        # A beam direction (towards the sensor) uniform in the tolerance cone; first the normal.
        side = rng.normal(size=n.shape)
        side -= np.sum(side * n, axis=1, keepdims=True) * n
        side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
        angle = 0.0 if k == 0 else tol_rad * np.sqrt(rng.random(len(n)))[:, None]
        beam = np.cos(angle) * n + np.sin(angle) * side
        todo = np.flatnonzero(~seen & (beam[:, 2] >= lowest))
        if len(todo):
            start = surface.points[todo] + 0.05 * n[todo]
            escapes = ~part.ray_engine.occluded(start, beam[todo], np.full(len(todo), 1e6))
            seen[todo] = escapes
    return float(seen.mean()) if len(seen) else 0.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--beams", type=int, default=24)
    args = ap.parse_args()
    tol = ScanSpec().tol_angle_rad
    print(f"part | ceiling, axis <= {VIEW_AXIS_MAX_TILT_DEG:g}° | ceiling, axis <= 90°")
    for name, units in PARTS.items():
        part = load_part(Path(args.parts_dir) / name, units)
        low = ceiling(part, tol, VIEW_AXIS_MAX_TILT_DEG, args.beams)
        high = ceiling(part, tol, 90.0, args.beams)
        print(f"{name} | {low:.3f} | {high:.3f}", flush=True)


if __name__ == "__main__":
    main()
