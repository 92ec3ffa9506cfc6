"""In-spec coverage of plans nominal and under perturbation, open loop (the plan replayed)
and, for feedback and rl plans, closed loop (the controller run on each perturbed part):
the README's robustness table. The figures are those of

    scanplan evaluate PART PLAN --points P --seed S --perturb SPEC --trials N [--closed-loop]

run here in one process, one trial after another (the command spreads them over the cores;
its pool gives the serial numbers). Usage:

    python benchmarks/robustness_table.py PART PLAN.json... [--units mm] [--points 256]
        [--trials 16] [--seed 0] [--perturb 'place:5mm,2deg']
        [--perturb 'place:2mm,1deg;warp:1mm@200mm'] [--loops open,closed]

Each row ends with the seconds it took (an HTML comment) and the plan's views.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from scanplan.core.context import recorded
from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.jobs.trials import CLOSED_LOOP_PLANNERS, closed_loop_robustness, closed_loop_tasks
from scanplan.judging import evaluate, robustness, trial_tasks
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import load_part

SPECS = ("place:5mm,2deg", "place:2mm,1deg;warp:1mm@200mm")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part")
    parser.add_argument("plans", nargs="+")
    parser.add_argument("--points", type=int, default=256)
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--perturb", action="append", default=None)
    parser.add_argument("--units", default="mm", help="units of a mesh file: mm, m or in")
    parser.add_argument(
        "--loops", default="open,closed", help="open, closed or both (closed: feedback, rl only)"
    )
    args = parser.parse_args()
    specs = args.perturb or list(SPECS)
    part = load_part(args.part, args.units)
    wanted = {loop.strip() for loop in args.loops.split(",")}
    header = " | ".join(f"{s}: mean / p5 / worst" for s in specs)
    print(f"| plan | loop | nominal | {header} |", flush=True)
    for path in args.plans:
        traj = read_trajectory(path)
        context = recorded(traj, ScanSpec())  # the file's own context (ScanSpec: if none)
        nominal = evaluate(
            part, context.spec, traj, args.seed, args.points, context=context
        ).in_spec_coverage
        loops = ["open"] + (["closed"] if context.planner in CLOSED_LOOP_PLANNERS else [])
        loops = [loop for loop in loops if loop in wanted]
        views = len(traj.meta.get("views") or [])
        for loop in loops:
            cells = []
            start = time.perf_counter()
            for text in specs:
                model = Perturbation.parse(text)
                if loop == "closed":
                    tasks = closed_loop_tasks(
                        part, traj, context, model, args.trials, args.seed, args.points
                    )
                    r = closed_loop_robustness(tasks)
                else:
                    r = robustness(
                        trial_tasks(
                            part,
                            context.spec,
                            traj,
                            model,
                            args.trials,
                            args.seed,
                            args.points,
                            context=context,
                        )
                    )
                cells.append(f"{r.mean:.3f} / {r.p5:.3f} / {r.worst:.3f}")
                record = {"plan": path, "loop": loop, "nominal": nominal, **r.to_json_dict()}
                print(json.dumps(record), file=sys.stderr, flush=True)
            print(
                f"| {context.planner} | {loop} | {nominal:.3f} | {' | '.join(cells)} |"
                f" <!-- {time.perf_counter() - start:.0f} s, {views} views -->",
                flush=True,
            )


if __name__ == "__main__":
    main()
