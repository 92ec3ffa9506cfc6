"""`scanplan defects`: the defects a plan would find. Seeded defects injected into the part,
the plan's scan of it simulated, hit/miss against size fitted as a POD curve (a50, a90,
a90/95), with the false calls the same plan makes on the defect-free part.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import progress_bar, user_errors
from scanplan.cli.evaluate import (
    EvaluateSchedulerOpt,
    OldViewsOpt,
    OtherPartOpt,
    PlanUnitsOpt,
    SurfaceOpt,
)
from scanplan.cli.options import (
    PartAndPlanArg,
    QuietOpt,
    SeedOpt,
    bounded,
    part_and_plan,
    surface_choice,
    within,
)
from scanplan.cli.training import check_cluster
from scanplan.core.limits import DEFECT_SIZE_MM, K_SIGMA, STEP_MM
from scanplan.core.quantities import (
    DEFECT_K_SIGMA,
    DEFECT_MIN_POINTS,
    DEFECT_SIZES_MM,
    DEFECT_TRIALS,
    DEFECT_TYPE,
    DEFECTS_PER_TRIAL,
)

TypeOpt = Annotated[str, typer.Option("--type", help="dent, bump, pit or scratch")]
SizesOpt = Annotated[
    str,
    typer.Option(
        help="LO:HI, the defects' depths in mm (a bump's height), spread evenly in log; "
        "the width follows the depth: dent and bump 10x (diameter), pit 4x, scratch 4x "
        "wide and 40x long"
    ),
]
DefectTrialsOpt = Annotated[
    int, typer.Option(help="trials (one defective part each)", callback=bounded(1, 10_000))
]
PerTrialOpt = Annotated[
    int,
    typer.Option(help="defects per trial, placed far apart", callback=bounded(1, 1000)),
]
KSigmaOpt = Annotated[
    float,
    typer.Option(
        "--k-sigma",
        help="a point is flagged where it departs from the nominal surface by more than this "
        "many standard deviations of the sensor noise there",
        callback=within(K_SIGMA),
    ),
]
MinPointsOpt = Annotated[
    int, typer.Option(help="flagged points a call needs", callback=bounded(1, 10_000))
]
DefectFreeOpt = Annotated[
    bool,
    typer.Option(
        "--defect-free/--no-defect-free",
        help="also scan the defect-free part with the plan: the false calls and the "
        "predicted detectability map (a full scan of the plan; off: faster)",
    ),
]
LinkOpt = Annotated[
    float | None,
    typer.Option(
        "--link",
        help="flagged points closer than this (mm) form one call; default: 1.5x the plan's "
        "median profile spacing (give the same value to compare plans under one rule)",
        callback=within(STEP_MM),
        show_default=False,
    ),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="print one JSON object")]
DirOpt = Annotated[
    Path | None,
    typer.Option(
        "-o",
        "--output",
        metavar="FOLDER",
        help="output folder: pod.json, pod.png, defects.csv and the detectability map",
    ),
]


# --sizes as typed: the default study's depths.
DEFAULT_SIZES = "{:g}:{:g}".format(*DEFECT_SIZES_MM)


def parse_sizes(text: str) -> tuple[float, float]:
    """'0.1:1.0' -> (0.1, 1.0) mm, each within `DEFECT_SIZE_MM`, LO <= HI."""
    lo_text, sep, hi_text = text.partition(":")
    try:
        lo = float(lo_text)
        hi = float(hi_text) if sep else lo
    except ValueError:
        raise ValueError(f"--sizes {text!r}: expected LO:HI in mm, e.g. 0.05:1.0") from None
    DEFECT_SIZE_MM.check(lo, "--sizes LO")
    DEFECT_SIZE_MM.check(hi, "--sizes HI")
    if lo > hi:
        raise ValueError(f"--sizes {text!r}: LO must be <= HI")
    return lo, hi


@user_errors
def defects_cmd(
    paths: PartAndPlanArg,
    kind: TypeOpt = DEFECT_TYPE,
    sizes: SizesOpt = DEFAULT_SIZES,
    trials: DefectTrialsOpt = DEFECT_TRIALS,
    per_trial: PerTrialOpt = DEFECTS_PER_TRIAL,
    seed: SeedOpt = 0,
    k_sigma: KSigmaOpt = DEFECT_K_SIGMA,
    min_points: MinPointsOpt = DEFECT_MIN_POINTS,
    link: LinkOpt = None,
    as_json: JsonOpt = False,
    output: DirOpt = None,
    units: PlanUnitsOpt = None,
    surface: SurfaceOpt = None,
    views: OldViewsOpt = None,
    scheduler: EvaluateSchedulerOpt = None,
    defect_free: DefectFreeOpt = True,
    quiet: QuietOpt = False,
    other_part: OtherPartOpt = False,
):
    """Inject seeded defects of one type at random places on the surface to inspect, simulate
    the plan's scan of each defective part, and fit the probability of detection against
    size (hit/miss, logistic on log size by maximum likelihood): a50, a90 and a90/95 (the
    95 % upper confidence bound on a90, delta method). A point is flagged where it departs
    from the nominal surface by more than k·σ of the sensor noise at it; flagged points
    form a call; a defect is found when a call lies on it. The false calls of the same plan
    on the defect-free part are reported beside."""
    # Deferred: the simulator loads trimesh and Embree (seconds), which --help need not.
    from scanplan.core.plan import read_plan
    from scanplan.jobs.defects import DefectStudy, defects_lines, run_defects, write_defects
    from scanplan.jobs.planned import judged_context, planned_part

    study = DefectStudy(
        kind, parse_sizes(sizes), trials, per_trial, seed, k_sigma, min_points, link,
        scheduler, defect_free,
    )  # fmt: skip
    check_cluster(scheduler, None)
    part, trajectory = part_and_plan(paths)
    plan = read_plan(trajectory)
    if not plan.traj.scanning.any():
        raise ValueError(f"trajectory {trajectory} has no scanning pose")
    mode, warning = surface_choice(surface, views, "defects")
    context, note = judged_context(plan, None, None, None, mode)
    say = lambda text: typer.echo(text, err=True)  # noqa: E731
    the_part = planned_part(plan, part, units, other_part=other_part, say=say)
    outcome = run_defects(plan, the_part, context, study, lambda label: progress_bar(label, quiet))
    if output is not None:
        write_defects(output, outcome, study, f"{the_part.name}: {trajectory.name}")
    for line in (warning, note):  # after the work: a command that fails says one line, its error
        if line:
            say(line)
    if as_json:
        typer.echo(json.dumps(outcome.data, allow_nan=False))
        return
    for line in defects_lines(outcome, study, output):
        typer.echo(line)
