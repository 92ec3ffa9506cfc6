"""The straight lines a robot program flies between targets farther apart than a move's
poses are planned (where the fit gave up poses of a move and kept those either side): for a
plan made for an arm (`scanplan plan PART --robot ...`), how many such lines it has, and on
how many the arm could not fly the way between (out of reach, past a joint limit, a flip, a
link or the sensor body in the cell), checked as `export` checks them and again at poses
`--step` mm apart (finer than the check's own). A plan from this release should have none.
Also the joint moves (into each pass, each detour and each lift): on how many the sensor
body comes within the plan's clearance of the cell (between poses that keep it: the fit's
standard), and into it (`export`'s), at the steps the links are checked at. A plan from
this release should have none.

    cd benchmarks && PYTHONPATH=../src python linear_gaps.py PLAN.json PART [--units m]

Without a plan, the built-in drone is planned for a KR 6 R900 (90 mm bracket, placed by
the tool) and its plan checked.
"""

from __future__ import annotations

import argparse

import numpy as np

from scanplan.core.plan import Plan
from scanplan.core.plan_file import read_json
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import pass_entries
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.rl.planners import make_planner
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.flyable import check_flyable
from scanplan.robot.joint_moves import sensor_swept
from scanplan.robot.links import obstacles_for
from scanplan.robot.presets import get_robot
from scanplan.robot.straight_moves import LINE_STEP_MM, blocked_steps, long_steps
from scanplan.world.cell import planned_cell
from scanplan.world.part import load_part


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("plan", nargs="?", help="a plan made for an arm (default: the drone's)")
    ap.add_argument("part", nargs="?")
    ap.add_argument("--units", default="mm")
    ap.add_argument("--step", type=float, default=0.5, help="mm between the poses checked")
    args = ap.parse_args()
    if args.plan is None:
        name, part = "drone, kr6-r900", load_part("drone", "mm")
        arm = Arm("kr6-r900", parse_pose_arg("0,0,90,0,0,0"))
        _, traj = plan_views(part, ScanSpec(), make_planner("geometric"), "auto", arm=arm)
    else:
        if args.part is None:
            raise SystemExit("give the plan's part after the plan")
        name, traj, part = args.plan, read_json(args.plan), load_part(args.part, args.units)
    plan = Plan.of(traj)  # the arm, its placement and entries as every command reads them
    if plan.arm is None:
        raise SystemExit(f"{name} is not a plan made for an arm")
    spec, robot = plan.spec, get_robot(plan.arm.robot)
    T_base_part, inv_tcp = plan.arm.T_base_part, np.linalg.inv(plan.arm.T_flange_sensor)
    cell = planned_cell(plan.context, part)
    obstacles = obstacles_for(part, cell, spec.sensor, spec.clearance_mm)
    # As `export` checks the plan: its joints, and the lines at the check's own spacing.
    checked = check_flyable(
        traj, robot, T_base_part, plan.arm.T_flange_sensor, part, cell, spec.sensor, obstacles
    )
    joints, entry = checked.joints, pass_entries(traj)
    lines = long_steps(traj, entry)
    length = np.linalg.norm(traj.positions_mm[lines] - traj.positions_mm[lines - 1], axis=1)
    finer = blocked_steps(
        robot, traj, T_base_part, inv_tcp, joints, entry, obstacles, None, args.step
    )
    found = [len(checked.blocked_lines), len(finer)]
    print(
        f"{name}: {len(traj)} poses, {len(lines)} straight lines across given-up poses (up "
        f"to {length.max() if len(lines) else 0:.0f} mm); the arm cannot fly {found[0]} of them "
        f"checked at {LINE_STEP_MM:g} mm, {found[1]} at {args.step:g} mm"
    )
    # The sensor body along the joint moves, as the fit and `export` check it.
    jointed = entry & (np.arange(len(traj)) > 0)
    tcp = plan.arm.T_flange_sensor
    near = sensor_swept(robot, joints, jointed, T_base_part, tcp, obstacles)
    into = checked.swept  # export's own verdict: into the cell
    print(
        f"{name}: {int(jointed.sum())} joint moves; the sensor body comes within "
        f"{spec.clearance_mm:g} mm of the cell on {len(near)} of them, into it on {len(into)}"
    )


if __name__ == "__main__":
    main()
