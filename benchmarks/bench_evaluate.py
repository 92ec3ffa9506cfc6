"""`evaluate`'s throughput next to the bare simulator's on the door's plans, in one run.

Plans the door once with every planner in its default configuration (as `scanplan plan door
--planner NAME`), then, for `--repeats` rounds, evaluates each plan as `scanplan evaluate`
does (`evaluate_detectable`: the in-spec map and the dent prediction, `--points` columns)
and measures the same scanning poses with a bare `LineProfilometer.measure_many` in the
same 256-pose chunks (the simulator alone), one after the other so a slow spell of a busy
machine hits both. Prints per planner the medians in profiles/s and their ratio (evaluate /
bare; 1.0 would be judging for free), and the figures the evaluation gives (to compare
between versions). The load average is printed too: on a busy machine the measuring thread
and the judging thread no longer run side by side.
Run: .venv/bin/python benchmarks/bench_evaluate.py [--points 256] [--repeats 3]
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

CONFIGS = {  # label: (planner, roll, raster), as bench_planning's defaults
    "fixed": ("fixed", False, "nominal"),
    "feedback": ("feedback", True, "auto"),
    "geometric": ("geometric", True, "auto"),
    "rl": ("rl", True, "auto"),
}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--points", type=int, default=256, help="evaluation fan (0 = full)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--planners", default=",".join(CONFIGS))
    args = parser.parse_args()

    part = load_part("door")
    spec = ScanSpec()
    sensor = spec.sensor.with_points(args.points) if args.points else spec.sensor
    points = args.points or None
    print(
        f"door: {len(part.mesh.faces)} triangles, {os.cpu_count()} cores, "
        f"{sensor.points_per_profile} columns, load average {os.getloadavg()[0]:.1f}"
    )
    for label in args.planners.split(","):
        name, roll, raster = CONFIGS[label]
        _, traj = plan_views(part, spec, make_planner(name, roll=roll), raster=raster)
        poses = traj.scan_poses
        evaluate_detectable(part, spec, traj, points_per_profile=points)  # samples, trees
        profiler = LineProfilometer(part, sensor)
        evals, bares = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            metrics = evaluate_detectable(part, spec, traj, points_per_profile=points)
            evals.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for i in range(0, len(poses), 256):  # the same chunking as evaluate
                profiler.measure_many(poses[i : i + 256])
            bares.append(time.perf_counter() - t0)
        eval_rate = len(poses) / statistics.median(evals)
        bare_rate = len(poses) / statistics.median(bares)
        a90 = (metrics.detectable or {}).get("a90_mm")
        print(
            f"{label:>10}: {len(poses)} profiles | evaluate {eval_rate:6.0f} profiles/s, "
            f"bare {bare_rate:6.0f} (ratio {eval_rate / bare_rate:.2f}; per round "
            f"{', '.join(f'{b / e:.2f}' for e, b in zip(evals, bares, strict=True))}) | "
            f"coverage {metrics.coverage_fraction:.5f} in-spec {metrics.in_spec_coverage:.5f} "
            f"a90 {a90:.4f} mm | load {os.getloadavg()[0]:.1f}"
        )


if __name__ == "__main__":
    main()
