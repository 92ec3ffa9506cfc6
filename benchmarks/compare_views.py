"""`--views top` vs `--views auto` on the real parts (../shared/parts): in-spec coverage
(of the upward-visible surface and of the surface visible from the upper hemisphere, and
the latter's visibility ceiling and share of it), views, passes and planning time (and its
ratio to the paper's single raster planned in the same run), geometric planner with its
default raster; and the view choice's own estimate of its greedy cover and of the exact one.
Then the same for the parts of other kinds made in `kinds.py` (a heightfield, a housing).

    PYTHONPATH=src python benchmarks/compare_views.py [PARTS_DIR] [--points 256]
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from pathlib import Path

from kinds import KINDS  # parts of kinds the shared set lacks (benchmarks/)

from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_scan
from scanplan.planning.pipeline import plan_views
from scanplan.rl.planners import make_planner
from scanplan.world.part import load_part

PARTS = {  # file: units (PARTS.md)
    "tum_ardrone_quadrotor_4.stl": "m",
    "nist_pmi1_stepped_plate.stl": "mm",
    "nist_pmi3_sheet_metal.stl": "mm",
    "nist_pmi4_pocket_plate.stl": "mm",
    "trimesh_featuretype.stl": "in",
    "reach_curved_panel_up.ply": "m",
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts_dir", nargs="?", default="../shared/parts")
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--only", default="", help="comma-separated parts of names to keep")
    args = ap.parse_args()
    spec = ScanSpec()
    planner = make_planner("geometric")
    paper = make_planner("geometric", roll=False)
    print(
        "part | views | passes | in-spec top-surface | in-spec hemisphere | ceiling | "
        "in-spec of ceiling | plan s (x the paper's raster) | "
        "choice estimate: greedy / exact, as many views (planned)"
    )
    for name, load in _parts(args.parts_dir):
        if args.only and not any(word in name for word in args.only.split(",")):
            continue
        part = load()
        # The reference measured in the same run: the paper's single raster (pitch only,
        # nominal passes, one top view).
        start = time.perf_counter()
        plan_scan(part, spec, paper, raster="nominal")
        t_paper = time.perf_counter() - start
        start = time.perf_counter()
        swaths, top = plan_scan(part, spec, planner)
        t_top = time.perf_counter() - start
        plans, auto = plan_views(part, spec, planner, "auto")
        for label, traj, n_view, n_pass, t in (
            ("top", top, 1, len(swaths), t_top),
            ("auto", auto, len(plans), sum(p.passes for p in plans), auto.plan_time_s),
        ):
            up = evaluate(
                part,
                spec,
                traj,
                points_per_profile=args.points,
                context=PlanContext(spec),
                ceiling=False,
            )
            hemi = evaluate(
                part,
                spec,
                traj,
                points_per_profile=args.points,
                context=PlanContext(spec, views="auto"),
            )
            print(
                f"{name} {label} | {n_view} | {n_pass} | {up.in_spec_coverage:.3f} | "
                f"{hemi.in_spec_coverage:.3f} | {hemi.visibility_ceiling:.3f} | "
                f"{hemi.in_spec_of_ceiling:.3f} | {t:.1f} ({t / t_paper:.1f}x) | {_choice(traj)}",
                flush=True,
            )


def _parts(parts_dir: str):
    """(name, loader) for the shared parts, then the kinds made in `kinds.py`."""
    for name, units in PARTS.items():
        yield name, partial(load_part, Path(parts_dir) / name, units)
    yield from KINDS.items()


def _choice(traj) -> str:
    c = traj.meta.get("view_choice")
    if c is None:
        return "-"
    return f"{c['in_spec_greedy']:.3f} / {c['in_spec_exact']:.3f} ({c['views_planned']})"


if __name__ == "__main__":
    main()
