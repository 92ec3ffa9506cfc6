"""Scan quality of the planners, side by side, on parts none of them was tuned on.

For each part and planner (each with its own default raster and views): plan, evaluate (noise on,
seed 0) and print in-spec coverage (the headline, `metrics.evaluate`), an independent check
of it from the simulated point cloud of `scanplan scan` (its per-point distance and
orientation error fields, area samples of the upward-visible surface, a sample counts if an
in-spec point lies within `--radius` mm), plain coverage, mean |distance| and orientation
errors, passes, profiles, cycle time and planning time.

Planners: fixed (the paper's baseline), geometric-v0 (the paper's model: pitch only, nominal
raster), feedback (the controller, with roll), geometric (roll + adaptive passes), rl (the
shipped policy).

Run: .venv/bin/python benchmarks/compare_planners.py [PART[:UNITS] ...] [--points 1024]
  PART is a built-in name (door, drone, training-piece) or a mesh file; default door drone.
  Example: ... door drone ../shared/parts/vito_left_car_door.obj:m \\
                ../shared/parts/trimesh_featuretype.stl:in
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import Metrics, evaluate
from scanplan.planning.pipeline import plan_views
from scanplan.planning.planners import Planner
from scanplan.rl.planners import make_planner
from scanplan.sensor.cloud import simulate_cloud
from scanplan.world.part import Part, load_part
from scanplan.world.surface import upward_visible_samples

PLANNERS: dict[str, tuple[str, bool, str]] = {  # label: (planner, roll, raster)
    "fixed": ("fixed", False, "nominal"),
    "geometric-v0": ("geometric", False, "nominal"),
    "feedback": ("feedback", True, "auto"),
    "geometric": ("geometric", True, "auto"),
    "rl": ("rl", True, "auto"),
}


def cloud_in_spec(part: Part, spec: ScanSpec, traj: Trajectory, points: int, radius: float):
    """In-spec coverage from the point cloud alone: the check a user can run on the PLY."""
    cloud = simulate_cloud(part, spec.sensor.with_points(points), traj, seed=0)
    ok = (np.abs(cloud.distance_error_mm) <= spec.tolerance_mm) & (
        cloud.orientation_error_rad <= spec.tol_angle_rad
    )
    samples = upward_visible_samples(part, 2.0, seed=1).points
    near = cKDTree(cloud.points_part[ok]).query(samples, distance_upper_bound=radius)[0]
    return float(np.isfinite(near).mean())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("parts", nargs="*", default=["door", "drone"])
    parser.add_argument("--points", type=int, default=1024, help="columns per profile")
    parser.add_argument("--radius", type=float, default=1.0, help="cloud check radius, mm")
    parser.add_argument("--planners", default=",".join(PLANNERS))
    args = parser.parse_args()
    labels = args.planners.split(",")
    spec = ScanSpec()
    print(
        "per planner: in-spec (metrics) / in-spec (cloud check) / coverage / "
        "|dist err| mm / orient. err ° / views:passes / profiles / cycle s / plan s"
    )
    print(f"| part | {' | '.join(labels)} |")
    print("|---" * (len(labels) + 1) + "|")
    for arg in args.parts:
        path, _, units = arg.partition(":")
        part = load_part(path, units or "mm")
        cells = []
        for label in labels:
            name, roll, raster = PLANNERS[label]
            planner: Planner = make_planner(name, roll=roll)
            t0 = time.perf_counter()
            plans, traj = plan_views(part, spec, planner, raster=raster)  # default views
            plan_s = time.perf_counter() - t0
            passes = sum(p.passes for p in plans)
            m: Metrics = evaluate(
                part, spec, traj, points_per_profile=args.points, context=PlanContext(spec)
            )
            check = cloud_in_spec(part, spec, traj, args.points, args.radius)
            cells.append(
                f"{m.in_spec_coverage:.3f} / {check:.3f} / {m.coverage_fraction:.3f} / "
                f"{m.distance_error_mean_abs_mm:.2f} / {m.orientation_error_mean_deg:.1f} / "
                f"{len(plans)}:{passes} / {m.profiles} / {m.cycle_time_s:.0f} / {plan_s:.1f}"
            )
        print(f"| {Path(path).stem} | {' | '.join(cells)} |", flush=True)


if __name__ == "__main__":
    main()
