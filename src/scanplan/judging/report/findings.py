"""What a report tells beside the scan's figures, in plain words: the verdicts, the robot
program and its arm (placement, what the arm cost), the perturbation trials, the defects.
Each is a `Finding`, a heading and its lines, that the page shows near its top.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from scanplan.core.plan import free_and_flown
from scanplan.judging.robustness import Robustness
from scanplan.judging.verdict import Verdict


@dataclass(frozen=True)
class Finding:
    """A heading and its lines of plain text (no internal names: those are for the JSON)."""

    title: str
    lines: tuple[str, ...]

    def to_html(self) -> str:
        items = "".join(f"<li>{html.escape(line)}</li>" for line in self.lines)
        return f"<h2>{html.escape(self.title)}</h2><ul class='findings'>{items}</ul>"


@dataclass(frozen=True)
class Program:
    """A robot program a job wrote: its file (as named in the report's folder), language,
    targets and cycle time (s)."""

    file: str
    language: str
    targets: int
    cycle_s: float | None = None


def verdict_finding(verdicts: Sequence[Verdict]) -> Finding | None:
    """Pass or fail per criterion of --require; None when none was given."""
    if not verdicts:
        return None
    failed = sum(not v.passed for v in verdicts)
    head = "Verdict: pass" if not failed else f"Verdict: FAIL ({failed} of {len(verdicts)})"
    return Finding(head, tuple(v.line() for v in verdicts))


def arm_finding(
    robot: str,
    record: Mapping[str, Any],
    program: Program | None = None,
    tcp: str = "",
    note: str = "",
) -> Finding:
    """The arm a plan was made for, where the part sits, what the arm cost in coverage, and
    the program written for it (and a `note` after)."""
    lines = []
    if program is not None:
        cycle = f", cycle time {program.cycle_s:.1f} s" if program.cycle_s is not None else ""
        lines.append(
            f"Program {program.file} ({program.language}), {program.targets} targets{cycle}."
        )
    place = record.get("part_pose", "")
    lines.append(
        f"Arm {robot}; the part at {place} in the arm's base frame (x, y, z in mm, then "
        "A, B, C in degrees about z, y, x)"
        + (f"; the sensor at {tcp} on the flange." if tcp else ".")
    )
    if (coverage := free_and_flown(record)) is not None:
        free, flown = coverage
        lines.append(
            f"What the arm cost: in-spec coverage {free:.1%} without it, {flown:.1%} with it "
            f"({100 * (free - flown):.1f} points lost), as the planner estimated it with a "
            "sub-sampled line."
        )
    given_up = record.get("scanning_poses_given_up", {})
    lines.append(
        f"The arm gave up {sum(given_up.values())} scanning poses and "
        f"{record.get('moves_given_up', 0)} move poses it cannot reach or fly clear of the "
        f"cell; passes split where the arm would flip its configuration: "
        f"{record.get('passes_split', 0)}, turned half a turn about the beam: "
        f"{record.get('passes_turned', 0)}. What is left it flies (reach, joint limits and "
        "links checked)."
    )
    return Finding(f"Robot program and arm ({robot})", (*lines, *([note] if note else [])))


def robustness_finding(robust: Robustness | None, nominal: float) -> Finding | None:
    """How the in-spec coverage holds on perturbed parts; None when no trials ran."""
    if robust is None:
        return None
    loop = "its controller run again on each" if robust.closed_loop else "the plan replayed"
    return Finding(
        "Robustness under perturbation",
        (
            f"Perturbation {robust.spec}, seed {robust.seed}, {loop}.",
            f"In-spec coverage {nominal:.1%} as planned; over {len(robust.per_trial)} perturbed "
            f"trials mean {robust.mean:.1%}, p5 {robust.p5:.1%} (95 % of trials keep at "
            f"least this), worst {robust.worst:.1%}.",
            f"{robust.fragile_fraction:.1%} of the surface is fragile (in spec as planned, "
            "out of spec in some trial): see fragility.png and fragility.csv.",
        ),
    )
