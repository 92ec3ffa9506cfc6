"""Plans with external axes: the parts an arm alone cannot cover, planned with `--views auto`
(geometric) on a 90 mm bracket for the arm alone and with a turntable or a track, against the
plan made without an arm: in-spec coverage of the hemisphere surface free and flown (their
gap), the axes' travel, strict `export`'s exit code (the CLI on the plan file: reach, joint
limits, flips, the arm's links and the sensor in the cell with the axes' values per pose), the
cycle time `plan` records, and the planning time beside the arm alone's (a ratio).

    PYTHONPATH=src python benchmarks/axes_plans.py [PARTS_DIR] [--points 256] [--only NAME]
        [--no-alone]

Cases: the built-in drone on a UR5e with the preset turntable; the REACH curved panel (in
metres) on a KR 6 R900 with a 2 m track, and with the turntable as well; the quadrotor (in
metres) on a UR5e and a KR 6 R900 with the turntable.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from scanplan.core.plan import Plan
from scanplan.core.plan_file import write_json
from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.rl.planners import make_planner
from scanplan.robot.axes import POSITIONERS, ExternalAxes, track_of
from scanplan.robot.program import program_cycle
from scanplan.world.part import load_part

# The sensor 90 mm out from the flange along its axis: a profilometer on a short bracket.
TCP = np.eye(4)
TCP[2, 3] = 90.0
TRACK_MM = 2000.0


def cases(parts_dir: Path) -> list[tuple[str, str, str, str, ExternalAxes]]:
    """(name, part, units, arm, axes) of each case."""
    quadrotor = str(parts_dir / "tum_ardrone_quadrotor_4.stl")
    return [
        ("drone", "drone", "mm", "ur5e", POSITIONERS["turntable"]),
        (
            "reach_curved_panel_up",
            str(parts_dir / "reach_curved_panel_up.ply"),
            "m",
            "kr6-r900",
            ExternalAxes(track=track_of(TRACK_MM)),
        ),
        (
            "reach_curved_panel_up_both",
            str(parts_dir / "reach_curved_panel_up.ply"),
            "m",
            "kr6-r900",
            ExternalAxes(POSITIONERS["turntable"].turntable, track_of(TRACK_MM)),
        ),
        *(
            (f"quadrotor_{robot}", quadrotor, "m", robot, POSITIONERS["turntable"])
            for robot in ("ur5e", "kr6-r900")
        ),
    ]


def strict_export(traj, tmp: Path, name: str, suffix: str) -> int:
    """`scanplan export` (strict) on the plan written to a file: its exit code."""
    plan_file = tmp / f"{name}.json"
    write_json(traj, plan_file)
    out = tmp / f"{name}{suffix}"
    run = subprocess.run(
        [sys.executable, "-m", "scanplan", "export", str(plan_file), "-o", str(out)],
        capture_output=True,
        text=True,
    )
    if run.returncode:
        print(f"  export {name}: {run.stderr.strip().splitlines()[-1]}", flush=True)
    return run.returncode


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--only", default="", help="cases whose name contains this")
    ap.add_argument("--no-alone", action="store_true", help="skip the arm alone's rows")
    args = ap.parse_args()
    spec = ScanSpec()
    planner = make_planner("geometric")
    print(
        "part | arm | axes | in-spec free / flown (gap) | axes' travel | strict export exit |"
        " cycle s | plan s (ratio to the arm alone)"
    )
    print("---|---|---|---|---|---|---|---")
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(tmp_dir)
        for name, source, units, robot, axes in cases(Path(args.parts_dir)):
            if args.only and args.only not in name:
                continue
            part = load_part(source, units)
            _, free = plan_views(part, spec, planner, "auto", fixture_units=units)
            without = evaluate(part, spec, free, points_per_profile=args.points).in_spec_coverage
            t_alone = None
            rows = [(None, "arm alone")] * (not args.no_alone) + [(axes, axes.describe())]
            for with_axes, label in rows:
                start = time.perf_counter()
                _, traj = plan_views(
                    part,
                    spec,
                    planner,
                    "auto",
                    fixture_units=units,
                    arm=Arm(robot, TCP, None, with_axes),
                )
                seconds = time.perf_counter() - start
                t_alone = seconds if with_axes is None else t_alone
                flown = evaluate(part, spec, traj, points_per_profile=args.points).in_spec_coverage
                suffix = ".script" if robot.startswith("ur") else ".src"
                tag = f"{name}_{'axes' if with_axes else 'alone'}"
                code = strict_export(traj, tmp, tag, suffix)
                travel = traj.meta["robot"].get("external_axes", {}).get("travel", [])
                cycle = program_cycle(Plan.of(traj)).total_s
                ratio = f" ({seconds / t_alone:.1f}x)" if t_alone and with_axes else ""
                print(
                    f"{name} | {robot} | {label} | {without:.3f} / {flown:.3f} "
                    f"({flown - without:+.3f}) | {', '.join(f'{t:.0f}' for t in travel) or '-'} |"
                    f" {code} | {cycle:.0f} | {seconds:.0f}{ratio}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
