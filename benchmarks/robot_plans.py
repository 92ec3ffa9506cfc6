"""Plans an arm can fly: the shared real parts and the built-in drone planned with
`--views auto` (geometric) for a UR5e, a KUKA KR 6 R900 and an ABB IRB 2400, each placed by
the tool, against the same plan without an arm: in-spec coverage of the hemisphere surface
with and without the arm, scanning poses given up, passes split at a configuration flip,
whether export's checks pass (reach, joint limits, flips, the arm's links against the part
and the table block), and the planning time with the arm beside the planning time without
it (a ratio: this machine is noisy).

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
from scanplan.robot import check_reach, get_robot
from scanplan.robot.base import pose_arg
from scanplan.robot.links import check_links, obstacles_for
from scanplan.robot.reach import pass_starts
from scanplan.world.cell import planned_cell
from scanplan.world.part import load_part

# The sensor 90 mm out from the flange along its axis: a profilometer on a short bracket.
TCP = np.eye(4)
TCP[2, 3] = 90.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--only", default="")
    ap.add_argument("--robots", default="ur5e,kr6-r900,irb2400")
    args = ap.parse_args()
    spec = ScanSpec()
    planner = make_planner("geometric")
    parts = {"drone": "mm"} | {str(Path(args.parts_dir) / n): u for n, u in PARTS.items()}
    print(
        "part | robot | --part-pose | in-spec without / with the arm | scanning poses given up"
        " | passes split | flyable: reach and links (export's checks) | plan s with / without"
        " (ratio)"
    )
    print("---|---|---|---|---|---|---|---")
    for name, units in parts.items():
        if args.only and args.only not in name:
            continue
        part = load_part(name, units)
        start = time.perf_counter()
        _, free = plan_views(part, spec, planner, "auto")
        t_free = time.perf_counter() - start
        without = evaluate(part, spec, free, points_per_profile=args.points)
        for robot in args.robots.split(","):
            start = time.perf_counter()
            _, traj = plan_views(part, spec, planner, "auto", arm=Arm(robot, TCP))
            t_arm = time.perf_counter() - start
            with_arm = evaluate(part, spec, traj, points_per_profile=args.points)
            fit = traj.meta["robot"]
            T_base_part = np.asarray(fit["T_base_part"])
            report = check_reach(
                T_base_part @ traj.poses @ np.linalg.inv(TCP),
                robot,
                swath=traj.swath,
                scanning=traj.scanning,
            )
            context = recorded(traj, spec)
            assert context.surface == "hemisphere"
            links = check_links(
                get_robot(robot),
                report.joints,
                obstacles_for(part, planned_cell(context, part), clearance_mm=spec.clearance_mm),
                T_base_part,
                pass_starts(traj.swath, traj.scanning),
            )
            flyable = report.reachable and links.clear
            print(
                f"{part.name} | {robot} | {pose_arg(T_base_part)} | "
                f"{without.in_spec_coverage:.3f} / {with_arm.in_spec_coverage:.3f} | "
                f"{sum(fit['scanning_poses_given_up'].values())} of {int(free.scanning.sum())}"
                f" | {fit['passes_split']} | {'yes' if flyable else 'NO'} | "
                f"{t_arm:.1f} / {t_free:.1f} ({t_arm / t_free:.1f}x)",
                flush=True,
            )


if __name__ == "__main__":
    main()
