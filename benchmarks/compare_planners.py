"""Scan quality of the three planners, side by side, on parts none of them was tuned on.

For each part: plan `fixed`, `geometric` and `rl` (the shipped policy) over the same base path,
evaluate each (noise on, seed 0) and print mean |distance error|, mean orientation error,
spacing CV, backward steps and coverage, then the ratios the issues judge by (rl / fixed,
rl / geometric, geometric / fixed), measured in the same run.

Run: .venv/bin/python benchmarks/compare_planners.py [PART[:UNITS] ...] [--points 1024]
  PART is a built-in name (door, drone, training-piece) or a mesh file; default door drone.
  Example: ... door drone ../shared/parts/vito_left_car_door.obj:m \
                ../shared/parts/trimesh_featuretype.stl:in
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from scanplan.metrics import Metrics, evaluate
from scanplan.part import load_part
from scanplan.planners import make_planner, plan_path
from scanplan.quantities import ScanSpec
from scanplan.swaths import plan_swaths

PLANNERS = ("fixed", "geometric", "rl")


def cell(m: Metrics) -> str:
    return (
        f"{m.distance_error_mean_abs_mm:6.2f} / {m.orientation_error_mean_deg:5.2f} / "
        f"{m.spacing_cv:.2f} / {m.backward_steps} / {m.coverage_fraction:.3f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("parts", nargs="*", default=["door", "drone"])
    parser.add_argument("--points", type=int, default=1024, help="columns per profile")
    parser.add_argument("--direction", default="auto")
    args = parser.parse_args()

    spec = ScanSpec()
    sensor = spec.sensor
    print("per planner: mean |dist err| mm / mean orient. err ° / spacing CV / backward / coverage")
    print(f"| part | {' | '.join(PLANNERS)} | rl/fixed d, o | rl/geo d | geo/fixed d, o |")
    print("|---|---|---|---|---|---|---|")
    for arg in args.parts:
        path, _, units = arg.partition(":")
        part = load_part(path, units or "mm")
        swaths = plan_swaths(part, sensor, args.direction)
        results: dict[str, Metrics] = {}
        seconds: dict[str, float] = {}
        for name in PLANNERS:
            t0 = time.perf_counter()
            traj = plan_path(part, spec, make_planner(name), swaths)
            results[name] = evaluate(part, spec, traj, points_per_profile=args.points)
            seconds[name] = time.perf_counter() - t0
        f, g, r = (results[n] for n in PLANNERS)

        def ratio(a: float, b: float) -> str:
            return f"{a / b:.2f}" if b > 0 else "n/a"

        print(
            f"| {Path(path).stem} ({len(swaths)} passes) | {cell(f)} | {cell(g)} | {cell(r)} | "
            f"{ratio(r.distance_error_mean_abs_mm, f.distance_error_mean_abs_mm)}, "
            f"{ratio(r.orientation_error_mean_deg, f.orientation_error_mean_deg)} | "
            f"{ratio(r.distance_error_mean_abs_mm, g.distance_error_mean_abs_mm)} | "
            f"{ratio(g.distance_error_mean_abs_mm, f.distance_error_mean_abs_mm)}, "
            f"{ratio(g.orientation_error_mean_deg, f.orientation_error_mean_deg)} |",
            flush=True,
        )
        print(
            "    seconds (plan+evaluate): " + ", ".join(f"{n} {s:.0f}" for n, s in seconds.items()),
            flush=True,
        )


if __name__ == "__main__":
    main()
