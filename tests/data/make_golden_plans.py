"""Record the golden plans the refactor test compares against (run once, before a change
that must not change results): door and drone, every planner in the paper's configuration
(nominal raster, no roll, the shipped v0 policy), every 25th pose + counts."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from scanplan.core.quantities import ScanSpec
from scanplan.planning.pass_path import plan_path
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.world.part import load_part

STRIDE = 25
PARTS = ("door", "drone")
PLANNERS = ("fixed", "geometric", "rl")


def golden_plans() -> dict[str, np.ndarray]:
    spec = ScanSpec()
    out: dict[str, np.ndarray] = {}
    for part_name in PARTS:
        part = load_part(part_name)
        swaths = plan_swaths(part, spec.sensor)
        for name in PLANNERS:
            traj = plan_path(part, spec, make_planner(name, roll=False), swaths)
            key = f"{part_name}/{name}"
            out[f"{key}/poses"] = traj.poses[::STRIDE]
            out[f"{key}/n"] = np.array([len(traj), int(traj.scanning.sum())])
            out[f"{key}/swath"] = traj.swath
    return out


if __name__ == "__main__":
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("golden_plans.npz")
    np.savez_compressed(path, **golden_plans())
    print(f"wrote {path}")
