"""Where the door's in-spec coverage is lost, and what holding it would cost.

Plans the built-in door with a planner in its default configuration (`scanplan plan door`),
evaluates it (`--points` columns, noise seed 0, upward-visible skin) and splits the surface
samples that are not in spec by where they lie: the window recess's walls by side (the upper
and lower walls run along x, the front and rear ones across it), its floor, the handle
pocket, a 20 mm band along the door's edge, and the rest; and by slope. Then prints what the
step model charges for a pitch excursion onto a wall that a pass crosses, next to the
profile budget (1.5x the paper's raster on the same door, planned in the same run).

Run: .venv/bin/python benchmarks/door_misses.py [--planner geometric] [--points 1024]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.spatial import cKDTree

from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec, StepLimits
from scanplan.judging import SurfaceState, evaluate
from scanplan.planning.pipeline import plan_views
from scanplan.rl.planners import make_planner
from scanplan.world.part import load_part
from scanplan.world.parts import door

SLOPES_DEG = (0, 30, 45, 60, 90)
WALL_BAND_MM = 2.0  # beyond the recess's smoothstep wall, each side


def regions(points: np.ndarray) -> dict[str, np.ndarray]:
    """Masks of the door's features at the samples (`parts.door`'s own geometry)."""
    x, y = points[:, 0], points[:, 1]
    wx, wy = door.WINDOW_CENTRE_MM
    why = door.WINDOW_HALF_MM[1]
    sheared = x - wx - door._WINDOW_SHEAR * (y - wy)
    sd_window = door._rounded_rect_sd(sheared, y - wy, door.WINDOW_HALF_MM, door._WINDOW_CORNER_MM)
    wall = (sd_window > -door._WINDOW_WALL_MM - WALL_BAND_MM) & (sd_window < WALL_BAND_MM)
    side = why - door._WINDOW_CORNER_MM  # the straight part of the upper and lower walls
    upper, lower = wall & (y - wy > side), wall & (y - wy < -side)
    px, py = door.POCKET_CENTRE_MM
    sd_pocket = door._rounded_rect_sd(x - px, y - py, door.POCKET_HALF_MM, door._POCKET_CORNER_MM)
    edge = (np.abs(x) > door.HALF_X_MM - 20) | (np.abs(y) > door.HALF_Y_MM - 20)
    out = {
        "window wall, upper (faces -y)": upper,
        "window wall, lower (faces +y)": lower,
        "window wall, front and rear": wall & ~upper & ~lower,
        "window floor": sd_window <= -door._WINDOW_WALL_MM - WALL_BAND_MM,
        "handle pocket": (sd_pocket < WALL_BAND_MM) & ~wall,
    }
    taken = np.logical_or.reduce(list(out.values()))
    out["edge band (20 mm)"] = edge & ~taken
    out["rest"] = ~taken & ~edge
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--planner", default="geometric")
    parser.add_argument("--points", type=int, default=1024, help="evaluation fan columns")
    args = parser.parse_args()
    spec = ScanSpec()
    part = load_part("door")
    _, paper = plan_views(part, spec, make_planner("geometric", roll=False), raster="nominal")
    _, traj = plan_views(part, spec, make_planner(args.planner))
    m = evaluate(part, spec, traj, points_per_profile=args.points, context=PlanContext(spec))
    assert m.coverage_map is not None
    points, state = m.coverage_map.points_part, m.coverage_map.state
    missed = state != SurfaceState.IN_SPEC
    n = len(state)
    print(f"door, {args.planner}: in-spec {m.in_spec_coverage:.3f}, {m.profiles} profiles")
    print("| where | share of surface | not in spec (share of surface) | of it unseen |")
    print("|---|---:|---:|---:|")
    for name, mask in regions(points).items():
        lost = mask & missed
        unseen = mask & (state == SurfaceState.UNSEEN)
        print(f"| {name} | {mask.mean():.4f} | {lost.mean():.4f} | {unseen.mean():.4f} |")
    # The face under each sample, near enough: the nearest face centre (cells of 1-4 mm).
    nearest = cKDTree(part.mesh.triangles_center).query(points)[1]
    faces = part.ray_engine.face_normals[nearest]
    slope = np.degrees(np.arccos(np.clip(np.abs(faces[:, 2]), 0.0, 1.0)))
    print("| slope | share of surface | not in spec (share of surface) | |")
    for lo, hi in zip(SLOPES_DEG[:-1], SLOPES_DEG[1:], strict=True):
        mask = (slope >= lo) & (slope < hi)
        print(f"| {lo}-{hi}° | {mask.mean():.4f} | {(mask & missed).mean():.4f} | |")
    print(f"samples: {n}")

    # A wall a pass crosses needs a pitch excursion with the footprint held on it: the
    # sensor swings W_d per radian, and the step model moves it at most Δy, Δz per step.
    lim, wd = StepLimits(), spec.working_distance_mm
    per_step = min(lim.dtheta_max_rad, math.hypot(lim.dy_max_mm, lim.dz_max_mm) / wd)
    for tilt in (45.0, 60.0):
        steps = 2 * math.radians(tilt) / per_step
        print(f"pitch excursion to {tilt:.0f}° and back: >= {steps:.0f} profiles per crossing")
    budget = int(1.5 * paper.scanning.sum())
    print(
        f"profile budget: 1.5 x {int(paper.scanning.sum())} (paper's raster) = {budget}; "
        f"this plan {m.profiles}, left {budget - m.profiles}"
    )


if __name__ == "__main__":
    main()
