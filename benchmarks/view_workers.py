"""The view choice (`--views auto`, geometric) on worker processes, one per core, against the
same choice planned in this process alone, back to back on each part (shared parts, then the
kinds of `kinds.py`): wall seconds of each and their ratio, and whether both chose the same
views (they must: the workers only plan ahead of the choice).

    PYTHONPATH=src python benchmarks/view_workers.py [PARTS_DIR] [--only a,b]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from compare_views import _parts  # the shared parts and the kinds, as compare_views loads them

from scanplan.core.quantities import OVERLAP, ScanSpec
from scanplan.planning.pass_path import ViewRaster
from scanplan.planning.view_choice import choose_views
from scanplan.planning.view_workers import view_worker_count
from scanplan.rl.planners import make_planner
from scanplan.world.cell import Cell


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--only", default="", help="comma-separated parts of names to keep")
    args = ap.parse_args()
    spec = ScanSpec()
    planner = make_planner("geometric")
    workers = view_worker_count()
    print(f"{os.cpu_count()} cores, {workers} workers")
    print("part | views | planned | alone s | on workers s | ratio | same views")
    ratios = []
    for name, load in _parts(args.parts_dir):
        if args.only and not any(word in name for word in args.only.split(",")):
            continue
        part = load()
        plan = ViewRaster(spec, planner, "auto", "auto", OVERLAP, Cell.around(part))
        times, picks = [], []
        for n in (0, workers):
            start = time.perf_counter()
            selection = choose_views(part, spec, plan, workers=n)
            times.append(time.perf_counter() - start)
            picks.append(selection)
        same = len(picks[0].plans) == len(picks[1].plans) and all(
            np.array_equal(a.traj.poses, b.traj.poses)
            for a, b in zip(picks[0].plans, picks[1].plans, strict=True)
        )
        ratios.append(times[1] / times[0])
        print(
            f"{name} | {len(picks[1].plans)} | {len(picks[1].in_spec)} | {times[0]:.1f} | "
            f"{times[1]:.1f} | {ratios[-1]:.2f} | {'yes' if same else 'NO'}",
            flush=True,
        )
    print(f"median ratio (on workers / alone): {float(np.median(ratios)):.2f}")


if __name__ == "__main__":
    main()
