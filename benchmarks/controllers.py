"""The controllers compared on the same views and pass lines (issue 45): one plan per part,
chosen once on the nominal CAD (the geometric planner's, pitch only, so every controller
below acts in the same step model; with --roll all roll, the policy v1), then, on each
of N perturbed parts (seeded):

- `geometric, replayed`: that plan's poses flown open loop (`evaluate --perturb`);
- `feedback` / `rl default` / `rl paper`: the controller flies the plan's pass lines in
  closed loop on the part as built and where it lies (`evaluate --closed-loop`, but every
  controller on the same lines);
- `ceiling`: the geometric planner re-planned on the same pass lines on the part as it is
  (it knows the part exactly): the best geometric answer on these lines (not an upper
  bound on in-spec coverage: the planner minimizes its own cost).

All are judged on the same nominal surface samples (the plan's), with the plan's sensor
noise; `nominal` is each controller on the unperturbed part. Usage:

    python benchmarks/controllers.py PART[:UNITS] [PART[:UNITS]...] [--views top] [--roll]
        [--points 128] [--trials 16] [--seed 0] [--perturb SPEC]... [--policy NAME]...
        [--json results.jsonl]

    python benchmarks/controllers.py --summary results.jsonl   # the table and the verdict

--policy takes a shipped policy's name or a policy folder (`scanplan train -o FOLDER`);
folders named NAME_s0, NAME_s1, ... (one per seed) are also summarized together, as the
mean and spread over the seeds of their p5 less feedback's.

A part is a built-in name, a mesh file (`:m`, `:in` for its units) or `kinds:NAME`, a part
of `benchmarks/kinds.py` (e.g. `kinds:housing`). Prints one markdown row per part,
perturbation and controller (nominal, mean, p5, worst), the seconds each took in an HTML
comment; --json appends the same records, one JSON line each, with the per-trial figures.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

from scanplan.core.context import recorded
from scanplan.core.quantities import ScanSpec
from scanplan.jobs.trials import closed_loop_robustness, controller_tasks
from scanplan.judging import robustness, trial_tasks
from scanplan.judging.robustness import Robustness
from scanplan.planning.pipeline import plan_views
from scanplan.planning.planners import FeedbackPlanner, GeometricPlanner
from scanplan.rl.planner import RLPlanner
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import Part, load_part

SPECS = ("place:2mm,1deg;warp:1mm@200mm", "place:5mm,2deg")


def the_part(text: str) -> Part:
    """`kinds:NAME`, a built-in part, or a mesh file with `:UNITS` (mm by default)."""
    if text.startswith("kinds:"):
        import kinds  # benchmarks/kinds.py, beside this script

        return getattr(kinds, text.removeprefix("kinds:"))()
    path, _, units = text.partition(":")
    return load_part(path, units or "mm")


def controllers(policies: list[str], roll: bool) -> list[tuple[str, Any]]:
    """(label, planner) of every closed-loop controller: feedback and each policy, all
    pitching only or (`roll`) all rolling too."""
    out: list[tuple[str, Any]] = [("feedback", FeedbackPlanner(roll=roll))]
    for name in policies:
        rl = RLPlanner.from_file(name)
        if rl.roll != roll:
            kind = "rolls" if rl.roll else "does not roll"
            raise SystemExit(f"policy {name} {kind}: give {'' if rl.roll else 'no '}--roll")
        out.append((f"rl {name}", rl))
    return out


def run_part(args: argparse.Namespace, text: str, out: Any) -> None:
    part = the_part(text)
    spec = ScanSpec()
    start = time.perf_counter()
    geometric = GeometricPlanner.with_roll() if args.roll else GeometricPlanner()
    _, plan = plan_views(part, spec, geometric, args.views)
    context = recorded(plan, spec)
    views = len(plan.meta.get("views") or [])
    passes = len(np.unique(plan.swath[plan.scanning]))
    print(
        f"\n{part.name}: {views} view(s), {passes} passes, planned in "
        f"{time.perf_counter() - start:.0f} s",
        flush=True,
    )
    print("| part | perturbation | controller | nominal | mean | p5 | worst |", flush=True)
    print("|---|---|---|---|---|---|---|", flush=True)
    zero = Perturbation()
    rows: list[tuple[str, Any, bool]] = [("geometric, replayed", None, False)]
    rows += [(label, planner, False) for label, planner in controllers(args.policy, args.roll)]
    rows.append(("ceiling (geometric re-planned)", geometric, True))
    if args.no_baselines:  # the policies alone: the seeded baselines of another run stand
        rows = [row for row in rows if row[0].startswith("rl ")]

    def judged(planner: Any, knows: bool, model: Perturbation, trials: int) -> Robustness:
        if planner is None:
            tasks = trial_tasks(
                part, spec, plan, model, trials, args.seed, args.points, context=context
            )
            return robustness(tasks)
        tasks = controller_tasks(
            part, plan, context, planner, model, trials, args.seed, args.points, knows_part=knows
        )
        return closed_loop_robustness(tasks)

    nominal = {label: judged(p, k, zero, 1).mean for label, p, k in rows if not k}
    for text_spec in args.perturb or list(SPECS):
        model = Perturbation.parse(text_spec)
        for label, planner, knows in rows:
            t0 = time.perf_counter()
            r = judged(planner, knows, model, args.trials)
            took = time.perf_counter() - t0
            nom = nominal.get(label)
            print(
                f"| {part.name} | {text_spec} | {label} | "
                f"{'—' if nom is None else f'{nom:.3f}'} | {r.mean:.3f} | {r.p5:.3f} | "
                f"{r.worst:.3f} | <!-- {took:.0f} s -->",
                flush=True,
            )
            if out is not None:
                record = {
                    "part": part.name,
                    "source": text,
                    "views": views,
                    "passes": passes,
                    "controller": label,
                    "nominal": nom,
                    "points": args.points,
                    "seconds": round(took, 1),
                    **r.to_json_dict(),
                }
                out.write(json.dumps(record) + "\n")
                out.flush()


# The criterion: closed-loop rl's p5 at least this far above closed-loop feedback's.
MARGIN = 0.02


def summary(path: str) -> None:
    """The records of `--json` as one table per perturbation (p5 / mean per controller,
    each policy's p5 less feedback's) and the parts on which each policy's p5 beats
    feedback's by `MARGIN`."""
    with open(path) as f:
        records = [json.loads(line) for line in f if line.strip()]
    parts = list(dict.fromkeys(r["part"] for r in records))
    labels = list(dict.fromkeys(r["controller"] for r in records))
    policies = [label for label in labels if label.startswith("rl ")]
    specs = list(dict.fromkeys(r["spec"] for r in records))
    at = {(r["part"], r["spec"], r["controller"]): r for r in records}
    for spec in specs:
        print(f"\n{spec}: p5 / mean in-spec coverage over {records[0]['trials']} trials\n")
        gaps = [f"{label} − feedback (p5)" for label in policies]
        print("| part | passes | " + " | ".join(labels + gaps) + " |")
        print("|---|---|" + "---|" * (len(labels) + len(gaps)))
        wins: dict[str, list[str]] = {label: [] for label in policies}
        done: dict[str, int] = {label: 0 for label in policies}
        for part in parts:
            mine = {label: at.get((part, spec, label)) for label in labels}
            cells = [
                "—" if r is None else f"{r['p5']:.3f} / {r['mean']:.3f}" for r in mine.values()
            ]
            feedback = mine.get("feedback")
            for label in policies:
                r = mine[label]
                if r is None or feedback is None:
                    cells.append("—")
                    continue
                gap = r["p5"] - feedback["p5"]
                cells.append(f"{gap:+.3f}")
                done[label] += 1
                if gap >= MARGIN - 1e-12:
                    wins[label].append(part)
            passes = next(r["passes"] for r in mine.values() if r is not None)
            print(f"| {part} | {passes} | " + " | ".join(cells) + " |")
        print()
        for label in policies:
            print(
                f"- {label}: p5 at least {MARGIN} above feedback's on {len(wins[label])} of "
                f"{done[label]} parts ({', '.join(wins[label]) or 'none'})"
            )
        for stem, seeds in seed_groups(policies).items():
            print(f"- {stem} over seeds {', '.join(seeds)}: p5 less feedback's, mean ± sd")
            for part in parts:
                feedback = at.get((part, spec, "feedback"))
                gaps = [
                    at[(part, spec, label)]["p5"] - feedback["p5"]
                    for label in seeds
                    if feedback is not None and (part, spec, label) in at
                ]
                if gaps:
                    print(f"  - {part}: {np.mean(gaps):+.3f} ± {np.std(gaps, ddof=1):.3f}")


def seed_groups(labels: list[str]) -> dict[str, list[str]]:
    """Policies trained with several seeds, by their common name: labels ending in _sK
    (e.g. `rl robust_s0`, `rl robust_s1`) grouped under `rl robust`, two or more each."""
    groups: dict[str, list[str]] = {}
    for label in labels:
        stem, sep, seed = label.rpartition("_s")
        if sep and seed.isdigit():
            groups.setdefault(stem, []).append(label)
    return {stem: seeds for stem, seeds in groups.items() if len(seeds) > 1}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("parts", nargs="*")
    parser.add_argument("--summary", default=None, help="print the table of a --json file")
    parser.add_argument("--views", default="top")
    parser.add_argument("--points", type=int, default=128)
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--perturb", action="append", default=None)
    parser.add_argument("--policy", action="append", default=None)
    parser.add_argument(
        "--roll", action="store_true", help="every planner and controller rolls (policy v1)"
    )
    parser.add_argument(
        "--no-baselines",
        action="store_true",
        help="run the policies only (no replay, feedback or re-plan); --summary a file that "
        "joins these records to a run's with the same parts, seed and trials",
    )
    parser.add_argument("--json", default=None, help="append the records here, a line each")
    args = parser.parse_args()
    if args.summary:
        summary(args.summary)
        return
    args.policy = args.policy or (["v1"] if args.roll else ["default", "paper"])
    out = open(args.json, "a") if args.json else None  # noqa: SIM115
    try:
        for text in args.parts:
            run_part(args, text, out)
    finally:
        if out is not None:
            out.close()


if __name__ == "__main__":
    main()
