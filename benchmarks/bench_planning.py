"""Planning and evaluation time on the built-in door, in one run.

Plans the door with every planner in its default configuration (default raster and views:
`scanplan plan door --planner NAME`) and, as the reference
measured in the same run, with the paper's configuration (`geometric-v0`: pitch only,
nominal raster — what planning cost before roll and adaptive passes). Prints each planning
time (median of `--repeats`) and its ratio to that reference, then evaluates each plan
(`--points` columns) as `scanplan evaluate` does (`evaluate_detectable`: the in-spec map and
the dent prediction) and prints the evaluation throughput in profiles/s next to a bare
`LineProfilometer.measure_many` of the same poses (the simulator alone): only ratios travel.
Run: .venv/bin/python benchmarks/bench_planning.py [--points N] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from scanplan.core.quantities import ScanSpec
from scanplan.judging.survey import evaluate_detectable
from scanplan.planning.pipeline import plan_views
from scanplan.rl.planners import make_planner
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import load_part

CONFIGS = {  # label: (planner, roll, raster)
    "geometric-v0": ("geometric", False, "nominal"),
    "fixed": ("fixed", False, "nominal"),
    "feedback": ("feedback", True, "auto"),
    "geometric": ("geometric", True, "auto"),
    "rl": ("rl", True, "auto"),
}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--points", type=int, default=1024, help="evaluation fan (0 = full)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--bare-profiles", type=int, default=2000)
    args = parser.parse_args()

    part = load_part("door")
    spec = ScanSpec()
    sensor = spec.sensor.with_points(args.points) if args.points else spec.sensor
    print(f"door: {len(part.mesh.faces)} triangles, {os.cpu_count()} cores")
    reference = None
    for label, (name, roll, raster) in CONFIGS.items():
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            plans, traj = plan_views(part, spec, make_planner(name, roll=roll), raster=raster)
            times.append(time.perf_counter() - t0)
        plan_s = statistics.median(times)
        reference = reference or plan_s
        poses = traj.scan_poses
        t0 = time.perf_counter()
        metrics = evaluate_detectable(part, spec, traj, points_per_profile=args.points or None)
        eval_s = time.perf_counter() - t0
        bare = poses[: args.bare_profiles]
        profiler = LineProfilometer(part, sensor)
        t0 = time.perf_counter()
        for i in range(0, len(bare), 256):  # the same chunking as evaluate
            profiler.measure_many(bare[i : i + 256])
        bare_rate = len(bare) / (time.perf_counter() - t0)
        eval_rate = len(poses) / eval_s
        print(
            f"{label:>12}: plan {plan_s:6.2f} s (x{plan_s / reference:4.2f} geometric-v0) | "
            f"{len(plans)} view(s), {sum(p.passes for p in plans)} passes, "
            f"{len(poses)} profiles x {sensor.points_per_profile} | "
            f"evaluate {eval_rate:6.0f} profiles/s, bare {bare_rate:6.0f} "
            f"(ratio {eval_rate / bare_rate:.2f}) | in-spec {metrics.in_spec_coverage:.3f}"
        )


if __name__ == "__main__":
    main()
