"""Perturbation trials next to one evaluation of the same plan, in one run.

`scanplan evaluate PART PLAN --points 256 --perturb 'place:2mm,1deg' --trials 16` costs one
evaluation (`evaluate_detectable`) and the trials (`robustness` over `trial_tasks`, spread
on every core as the command spreads them). Prints both times and the ratio trials /
evaluation (the issue's target: 16 trials at most 4x one evaluation), and one trial run
here, in this process, next to the evaluation; and the bare simulator on the plan's
scanning poses (one thread), the least a trial costs: sixteen on the machine's cores take
at least 16 x that / cores. Default part: the NIST pocket plate of the
shared parts (mm; the built-in door without them), its plan made here by the geometric
planner unless --plan gives one (`scanplan plan PART -o plan.json`).
Run: .venv/bin/python benchmarks/bench_trials.py [--part PATH:UNITS] [--plan plan.json]
     [--points 256] [--trials 16] [--perturb 'place:2mm,1deg'] [--repeats 1]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.core.run import task_runner
from scanplan.judging.evaluation import scanning_steps
from scanplan.judging.robustness import robustness, run_trial, trial_tasks
from scanplan.judging.survey import evaluate_detectable
from scanplan.planning.pipeline import plan_views
from scanplan.rl.planners import make_planner
from scanplan.sensor.perturb import Perturbation
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import load_part

POCKET = Path(__file__).resolve().parents[2] / "shared/parts/nist_pmi4_pocket_plate.stl"


def main() -> None:
    parser = argparse.ArgumentParser()
    default = f"{POCKET}:mm" if POCKET.exists() else "door"  # without the shared parts
    parser.add_argument("--part", default=default, help="PATH:UNITS or a built-in")
    parser.add_argument("--plan", default=None, help="plan file (default: planned here)")
    parser.add_argument("--points", type=int, default=256)
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--perturb", default="place:2mm,1deg")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()

    path, _, units = args.part.rpartition(":") if ":" in args.part else (args.part, "", "mm")
    part = load_part(path, units or "mm")
    spec = ScanSpec()
    if args.plan:
        traj = read_trajectory(args.plan)
    else:
        _, traj = plan_views(part, spec, make_planner("geometric", roll=True), raster="auto")
    model = Perturbation.parse(args.perturb)
    print(
        f"{part.name}: {len(part.mesh.faces)} triangles, {int(traj.scanning.sum())} "
        f"profiles x {args.points}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    evals, alls, ones, bares = [], [], [], []
    poses = traj.poses[scanning_steps(traj)[0]]
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        metrics = evaluate_detectable(part, spec, traj, 0, args.points)
        evals.append(time.perf_counter() - t0)
        # The bare simulator on the same scanning poses, one thread: what a trial must at
        # least spend, since every ray of a perturbed scan differs from the nominal one's.
        profiler = LineProfilometer(part, spec.sensor.with_points(args.points), seed=0)
        t0 = time.perf_counter()
        for i in range(0, len(poses), 256):
            profiler.measure_many(poses[i : i + 256])
        bares.append(time.perf_counter() - t0)
        tasks = trial_tasks(part, spec, traj, model, args.trials, 0, args.points)
        t0 = time.perf_counter()
        with task_runner(None, args.trials) as run:
            robust = robustness(tasks, run)
        alls.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        run_trial(tasks[0])
        ones.append(time.perf_counter() - t0)
    ev, every, one, bare = (statistics.median(x) for x in (evals, alls, ones, bares))
    cores = os.cpu_count() or 1
    floor = args.trials * bare / cores
    print(f"one evaluation {ev:.1f} s (in-spec {metrics.in_spec_coverage:.4f})")
    print(
        f"bare simulator on its poses {bare:.1f} s (one thread): {args.trials} trials on "
        f"{cores} cores take at least {floor:.1f} s, {floor / ev:.2f} x one evaluation"
    )
    print(
        f"{args.trials} trials ({args.perturb}) {every:.1f} s: ratio {every / ev:.2f} x one "
        f"evaluation (target <= 4); mean {robust.mean:.4f}, worst {robust.worst:.4f}"
    )
    print(
        f"one trial in this process {one:.1f} s: ratio {one / ev:.2f} x one evaluation | "
        f"load {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
