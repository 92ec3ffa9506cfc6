"""The ceiling of any correction under perturbation: the plan's planner run again on each
perturbed part as it is (as built, where it lies: it knows the part exactly), judged as the
replayed plan's trials are (`evaluate --perturb`, same seed, same samples). What a closed
loop, a part localization or a learned correction could reach at most with that planner.

    python benchmarks/replan_ceiling.py door PLAN.json [--perturb 'place:5mm,2deg']
        [--trials 16] [--seed 0] [--points 256]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from scanplan.core.context import recorded
from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.judging import robustness, run_trial, trial_tasks
from scanplan.judging.evaluation import scanning_steps
from scanplan.judging.robustness import summarize, trial_world
from scanplan.planning.pipeline import plan_views
from scanplan.rl.planners import make_planner
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import Part, load_part


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part")
    parser.add_argument("plan")
    parser.add_argument("--perturb", default="place:5mm,2deg")
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--points", type=int, default=256)
    args = parser.parse_args()
    start = time.perf_counter()
    part = load_part(args.part)
    traj = read_trajectory(args.plan)
    context = recorded(traj, ScanSpec())
    spec = context.spec
    model = Perturbation.parse(args.perturb)
    tasks = trial_tasks(
        part, spec, traj, model, args.trials, args.seed, args.points, context=context
    )
    planner = make_planner(context.planner, roll=context.full_beam_angle)
    results = []
    for task in tasks:
        world = trial_world(task)
        mesh = world.part.mesh.copy()
        mesh.apply_transform(world.T_part_placed)  # the part as built, where it lies
        there = Part(mesh, name=part.name, source=part.source, inspect_faces=task.inspect_faces)
        _, replanned = plan_views(there, spec, planner, context.views, roi=context.roi)
        idx, has_prev = scanning_steps(replanned)
        results.append(run_trial(replace(task, poses=replanned.poses[idx], has_prev=has_prev)))
        print(f"trial {task.index}: {results[-1].mean():.3f}", flush=True)
    ceiling = summarize(tasks[0], results)
    replay = robustness(tasks)
    print(f"{args.trials} trials, seed {args.seed} ({model.text()}), {args.points} points")
    print("| plan | mean | p5 | worst |")
    print("|---|---|---|---|")
    for name, r in (("replayed", replay), (f"{context.planner} re-planned on each part", ceiling)):
        print(f"| {name} | {r.mean:.3f} | {r.p5:.3f} | {r.worst:.3f} |")
    print(f"({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
