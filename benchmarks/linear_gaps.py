"""The straight lines a robot program flies between targets that nothing checks: for a plan
made for an arm (`scanplan plan PART --robot ...`), every linear step (not into a joint
move) longer than `--longer-than` mm (moves are planned with poses at most
`motion.MOVE_STEP_MM` apart, so a longer step is where the fit gave up poses between),
interpolated at `--step` mm: does the sensor body come into the cell on the way, does a
link, does the arm leave its reach? The arm's joints along a step follow the branch
nearest those at its first pose.

    cd benchmarks && PYTHONPATH=../src python linear_gaps.py PLAN.json PART [--units m]

Without a plan, the built-in drone is planned for a KR 6 R900 (90 mm bracket, placed by
the tool) and its plan checked.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from scanplan.core.context import recorded
from scanplan.core.plan_file import read_json
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import pass_entries
from scanplan.planning.motion import MOVE_STEP_MM
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.rl.planners import make_planner
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.links import check_links, obstacles_for
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import check_reach
from scanplan.world.cell import planned_cell
from scanplan.world.part import load_part


def _along(poses: np.ndarray, i: int, step_mm: float) -> np.ndarray:
    """(k, 4, 4) poses strictly between poses i and i + 1, at most `step_mm` apart."""
    length = float(np.linalg.norm(poses[i + 1, :3, 3] - poses[i, :3, 3]))
    t = np.linspace(0.0, 1.0, max(3, int(np.ceil(length / step_mm)) + 1))[1:-1]
    out = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
    turn = Slerp([0.0, 1.0], Rotation.from_matrix(poses[[i, i + 1], :3, :3]))
    out[:, :3, :3] = turn(t).as_matrix()
    out[:, :3, 3] = poses[i, :3, 3] + t[:, None] * (poses[i + 1, :3, 3] - poses[i, :3, 3])
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("plan", nargs="?", help="a plan made for an arm (default: the drone's)")
    ap.add_argument("part", nargs="?")
    ap.add_argument("--units", default="mm")
    ap.add_argument("--longer-than", type=float, default=MOVE_STEP_MM, help="mm")
    ap.add_argument("--step", type=float, default=2.0, help="mm between interpolated poses")
    args = ap.parse_args()
    spec = ScanSpec()
    if args.plan is None:
        name, part = "drone, kr6-r900", load_part("drone", "mm")
        arm = Arm("kr6-r900", parse_pose_arg("0,0,90,0,0,0"))
        _, traj = plan_views(part, spec, make_planner("geometric"), "auto", arm=arm)
    else:
        if args.part is None:
            raise SystemExit("give the plan's part after the plan")
        name, traj, part = args.plan, read_json(args.plan), load_part(args.part, args.units)
    record = traj.meta.get("robot")
    if not isinstance(record, dict):
        raise SystemExit(f"{name} is not a plan made for an arm")
    obstacles = obstacles_for(
        part, planned_cell(recorded(traj, spec), part), spec.sensor, spec.clearance_mm
    )
    robot = get_robot(record["robot"])
    T_base_part = parse_pose_arg(record["part_pose"])
    inv_tcp = np.linalg.inv(parse_pose_arg(record["tcp"]))
    joints = check_reach(
        T_base_part @ traj.poses @ inv_tcp, robot, swath=traj.swath, scanning=traj.scanning
    ).joints
    length = np.linalg.norm(np.diff(traj.poses[:, :3, 3], axis=0), axis=1)
    long = np.flatnonzero(~pass_entries(traj)[1:] & (length > args.longer_than))
    sensor = links = reach = 0
    for i in long:
        between = _along(traj.poses, int(i), args.step)
        sensor += int(not obstacles.sensor_clear(between).all())
        q = robot.inverse(T_base_part @ between @ inv_tcp)  # (k, branches, 6)
        apart = np.abs(q - joints[i]).max(axis=-1)  # NaN: no solution on that branch
        nearest = q[np.arange(len(q)), np.argmin(np.nan_to_num(apart, nan=np.inf), axis=1)]
        solved = ~np.isnan(nearest).any(axis=1)
        reach += int(not solved.all())
        if solved.any():
            hit = check_links(robot, nearest[solved], obstacles, T_base_part).colliding
            links += int(hit.any())
    print(
        f"{name}: {len(traj)} poses, {len(long)} linear steps longer than "
        f"{args.longer_than:g} mm (up to {length[long].max() if len(long) else 0:.0f} mm); "
        f"on the way the sensor comes into the cell on {sensor}, a link on {links}, the arm "
        f"leaves its reach on {reach}"
    )


if __name__ == "__main__":
    main()
