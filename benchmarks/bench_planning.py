"""Planning and evaluation time on the built-in door, in one run.

Plans `fixed` and `geometric`, then evaluates each at full resolution (4096 columns) and
prints the evaluation throughput in profiles/s next to a bare `LineProfilometer.measure_many`
of the same poses (the simulator alone), measured in the same run: only the ratio travels.
Run: .venv/bin/python benchmarks/bench_planning.py [--points N] [--direction auto|x|y]
"""

from __future__ import annotations

import argparse
import os
import time

from scanplan.metrics import evaluate
from scanplan.part import load_part
from scanplan.planners import plan_path
from scanplan.planners.fixed import FixedPlanner
from scanplan.planners.geometric import GeometricPlanner
from scanplan.quantities import ScanSpec
from scanplan.sensor import LineProfilometer
from scanplan.swaths import plan_swaths


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--points", type=int, default=None, help="sub-sampled fan (default full)")
    parser.add_argument("--direction", default="auto")
    parser.add_argument("--bare-profiles", type=int, default=2000)
    args = parser.parse_args()

    part = load_part("door")
    spec = ScanSpec()
    sensor = spec.sensor.with_points(args.points) if args.points else spec.sensor
    swaths = plan_swaths(part, spec.sensor, args.direction)
    print(f"door: {len(part.mesh.faces)} triangles, {len(swaths)} passes, {os.cpu_count()} cores")
    for planner in (FixedPlanner(), GeometricPlanner()):
        t0 = time.perf_counter()
        traj = plan_path(part, spec, planner, swaths)
        plan_s = time.perf_counter() - t0
        poses = traj.scan_poses
        t0 = time.perf_counter()
        metrics = evaluate(part, spec, traj, points_per_profile=args.points)
        eval_s = time.perf_counter() - t0
        bare = poses[: args.bare_profiles]
        profiler = LineProfilometer(part, sensor)
        t0 = time.perf_counter()
        for i in range(0, len(bare), 256):  # the same chunking as evaluate
            profiler.measure_many(bare[i : i + 256])
        bare_rate = len(bare) / (time.perf_counter() - t0)
        eval_rate = len(poses) / eval_s
        print(
            f"{planner.name:>9}: plan {plan_s:6.2f} s | {len(poses)} profiles x "
            f"{sensor.points_per_profile} | evaluate {eval_s:6.2f} s = {eval_rate:6.0f} profiles/s "
            f"| bare measure_many {bare_rate:6.0f} profiles/s | ratio {eval_rate / bare_rate:.2f} "
            f"| mean |dist err| {metrics.distance_error_mean_abs_mm:.2f} mm"
        )


if __name__ == "__main__":
    main()
