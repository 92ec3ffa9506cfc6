"""Plans an arm can fly: the shared real parts and the built-in drone planned with
`--views auto` (geometric) for a UR5e, a KUKA KR 6 R900 and an ABB IRB 2400 on a 90 mm
bracket, each placed by the tool, against the plan made without an arm: in-spec coverage of
the hemisphere surface free and flown (and their difference), the scanning poses given up
by cause (of those the views chosen for the arm planned), passes split, whether export's
check passes (`check_flyable`: reach, joint limits, flips, the arm's links and the sensor
body against the part, fixtures and table), and the planning time with the arm beside the
time without it (a ratio: this machine is noisy) and whether it is within its allowance
(`allowance`).

    PYTHONPATH=src python benchmarks/robot_plans.py [PARTS_DIR] [--points 256] [--only NAME]
        [--robots ur5e,kr6-r900,irb2400]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from compare_views import PARTS

from scanplan.core.context import recorded
from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.rl.planners import make_planner
from scanplan.robot import get_robot
from scanplan.robot.base import pose_arg
from scanplan.robot.flyable import check_flyable
from scanplan.world.cell import planned_cell
from scanplan.world.part import load_part

# The sensor 90 mm out from the flange along its axis: a profilometer on a short bracket.
TCP = np.eye(4)
TCP[2, 3] = 90.0


def allowance(free_s: float) -> float:
    """The planning time allowed with an arm: 3x the plan without it, or 20 s more,
    whichever is larger."""
    return max(3.0 * free_s, free_s + 20.0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--only", default="", help="parts whose name contains this (a,b: any)")
    ap.add_argument("--robots", default="ur5e,kr6-r900,irb2400")
    args = ap.parse_args()
    spec = ScanSpec()
    planner = make_planner("geometric")
    parts = {"drone": "mm", "door": "mm"}
    parts |= {str(Path(args.parts_dir) / n): u for n, u in PARTS.items()}
    print(
        "part | robot | --part-pose | in-spec free / flown (gap) | scanning poses given up"
        " by cause | passes split | export's check | plan s with / without (ratio, allowance)"
    )
    print("---|---|---|---|---|---|---|---")
    for name, units in parts.items():
        if args.only and not any(o in name for o in args.only.split(",")):
            continue
        part = load_part(name, units)
        start = time.perf_counter()
        _, free = plan_views(part, spec, planner, "auto")
        t_free = time.perf_counter() - start
        without = evaluate(part, spec, free, points_per_profile=args.points).in_spec_coverage
        for robot in args.robots.split(","):
            start = time.perf_counter()
            try:
                _, traj = plan_views(part, spec, planner, "auto", arm=Arm(robot, TCP))
            except ValueError as e:  # an arm that reaches nothing of it: a row that says so
                print(f"{part.name} | {robot} | - | {without:.3f} / - | {e} | | | ", flush=True)
                continue
            t_arm = time.perf_counter() - start
            flown = evaluate(part, spec, traj, points_per_profile=args.points).in_spec_coverage
            fit = traj.meta["robot"]
            T_base_part = np.asarray(fit["T_base_part"])
            context = recorded(traj, spec)
            assert context.surface == "hemisphere"
            cell = planned_cell(context, part)
            check = check_flyable(traj, get_robot(robot), T_base_part, TCP, part, cell, spec.sensor)
            causes: dict[str, int] = {}
            for by in fit["given_up_by_cause"].values():
                for cause, count in by.items():
                    causes[cause] = causes.get(cause, 0) + count
            given_up = ", ".join(f"{c} {k}" for k, c in sorted(causes.items(), key=lambda i: -i[1]))
            print(
                f"{part.name} | {robot} | {pose_arg(T_base_part)} | "
                f"{without:.3f} / {flown:.3f} ({flown - without:+.3f}) | "
                f"{sum(causes.values())} of {int(traj.scanning.sum()) + sum(causes.values())}"
                f"{f' ({given_up})' if given_up else ''} | {fit['passes_split']} | "
                f"{'flyable' if check.flyable else 'NOT: ' + check.first_problem(traj.swath)} | "
                f"{t_arm:.1f} / {t_free:.1f} ({t_arm / t_free:.1f}x, "
                f"{'within' if t_arm <= allowance(t_free) else 'over'} "
                f"{allowance(t_free):.1f})",
                flush=True,
            )


if __name__ == "__main__":
    main()
