"""Verdicts: the figures a plan is judged by, each with one name (`--require`, tables, JSON)
and one plain label (text, reports), and the criteria `--require "in-spec>=0.9,cycle<=120s"`
holds them to, pass or fail.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from scanplan.core.plan import free_and_flown
from scanplan.judging.robustness import Robustness
from scanplan.judging.summary import Metrics


@dataclass(frozen=True)
class Figure:
    """A figure a plan is judged by: `key` as --require and the JSON name it, `label` as
    the text does, `unit` one of fraction (0.9 or 90%), s, mm, count; `high` whether more is
    better (how a table sorts hardest first)."""

    key: str
    label: str
    unit: str
    high: bool = True

    def show(self, value: float | None) -> str:
        """The value as the text prints it: fractions as percent, times in s, depths in mm."""
        if value is None or not math.isfinite(value):
            return "n/a"
        if self.unit == "fraction":
            return f"{value:.1%}"
        if self.unit == "s":
            return f"{value:.1f} s"
        if self.unit == "mm":
            return f"{value:.3g} mm"
        return f"{value:g}"


FIGURES = {
    f.key: f
    for f in (
        Figure("in-spec", "in-spec coverage", "fraction"),
        Figure("ceiling", "visibility ceiling", "fraction"),
        Figure("of-ceiling", "in-spec coverage as a share of the visibility ceiling", "fraction"),
        Figure("coverage", "coverage (any valid point)", "fraction"),
        Figure("arm-cost", "in-spec coverage the arm cost", "fraction", high=False),
        Figure("cycle", "cycle time", "s", high=False),
        Figure("p5", "in-spec coverage under perturbation, p5", "fraction"),
        Figure("worst", "in-spec coverage under perturbation, worst trial", "fraction"),
        Figure("a90", "dent depth found 90 % of the time (predicted)", "mm", high=False),
        Figure("pod-a90", "dent depth found 90 % of the time (defect trials)", "mm", high=False),
        Figure(
            "collisions", "poses closer to the part or cell than the clearance", "count", high=False
        ),
    )
}
_OPS = {
    ">=": lambda v, x: v >= x,
    "<=": lambda v, x: v <= x,
    ">": lambda v, x: v > x,
    "<": lambda v, x: v < x,
}
_CRITERION = re.compile(r"\s*([a-z0-9-]+)\s*(>=|<=|>|<)\s*([0-9.eE+-]+)\s*([a-z%]*)\s*")
_UNIT_SCALE = {
    "fraction": {"": 1.0, "%": 0.01},
    "s": {"": 1.0, "s": 1.0, "min": 60.0, "h": 3600.0},
    "mm": {"": 1.0, "mm": 1.0, "um": 0.001, "m": 1000.0},
    "count": {"": 1.0},
}


@dataclass(frozen=True)
class Criterion:
    """One requirement: `figure` `op` `limit` (in the figure's unit: fraction, s, mm)."""

    figure: Figure
    op: str
    limit: float
    text: str

    def holds(self, value: float | None) -> bool:
        """Whether `value` meets it; a figure not reached (None, NaN) fails."""
        return value is not None and math.isfinite(value) and _OPS[self.op](value, self.limit)


@dataclass(frozen=True)
class Verdict:
    """A criterion and the value it was held to."""

    criterion: Criterion
    value: float | None

    @property
    def passed(self) -> bool:
        return self.criterion.holds(self.value)

    def line(self) -> str:
        c = self.criterion
        return (
            f"{'pass' if self.passed else 'FAIL'}: {c.figure.label} {c.figure.show(self.value)} "
            f"(required {c.op} {c.figure.show(c.limit)})"
        )

    def to_json_dict(self) -> dict[str, Any]:
        c = self.criterion
        value = self.value if self.value is not None and math.isfinite(self.value) else None
        return {
            "criterion": c.text,
            "figure": c.figure.key,
            "op": c.op,
            "limit": c.limit,
            "value": value,
            "pass": self.passed,
        }


def parse_requirements(text: str) -> tuple[Criterion, ...]:
    """`--require "in-spec>=0.9,cycle<=120s,p5>=80%"` as criteria, or a one-line ValueError
    naming the bad one."""
    criteria = []
    for part in text.split(","):
        if not part.strip():
            continue
        match = _CRITERION.fullmatch(part.lower())
        if match is None:
            raise ValueError(
                f"--require {part.strip()!r}: expected NAME>=VALUE or NAME<=VALUE, e.g. "
                "'in-spec>=0.9,cycle<=120s'"
            )
        key, op, number, unit = match.groups()
        if key not in FIGURES:
            raise ValueError(
                f"--require {part.strip()!r}: unknown figure {key!r}; use {', '.join(FIGURES)}"
            )
        figure = FIGURES[key]
        scales = _UNIT_SCALE[figure.unit]
        if unit not in scales:
            units = ", ".join(repr(u) for u in scales if u) or "none"
            raise ValueError(f"--require {part.strip()!r}: {key} takes the units {units}")
        try:
            limit = float(number) * scales[unit]
        except ValueError:
            raise ValueError(f"--require {part.strip()!r}: {number!r} is not a number") from None
        if not math.isfinite(limit):
            raise ValueError(f"--require {part.strip()!r}: {number!r} is not a finite number")
        criteria.append(Criterion(figure, op, limit, part.strip()))
    if not criteria:
        raise ValueError("--require names no criterion: e.g. 'in-spec>=0.9,cycle<=120s'")
    return tuple(criteria)


def check_available(criteria: tuple[Criterion, ...], missing: Mapping[str, str]) -> None:
    """A ValueError before any work if a criterion needs a figure this run will not
    measure; `missing` maps such figures to what would (e.g. 'p5': 'give --perturb')."""
    for c in criteria:
        if c.figure.key in missing:
            raise ValueError(f"--require {c.text!r}: {c.figure.label} {missing[c.figure.key]}")


def judge(criteria: tuple[Criterion, ...], figures: Mapping[str, float | None]) -> list[Verdict]:
    return [Verdict(c, figures.get(c.figure.key)) for c in criteria]


def figures_of(
    metrics: Metrics | None = None,
    robust: Robustness | None = None,
    arm: Mapping[str, Any] | None = None,
    cycle_s: float | None = None,
    pod_a90_mm: float | None = None,
) -> dict[str, float | None]:
    """The figures of one plan, by `FIGURES` key, from what was measured: its evaluation,
    its perturbation trials, its arm's record (the plan's meta["robot"]), its defect trials."""
    out: dict[str, float | None] = {}
    if metrics is not None:
        found = metrics.detectable or {}
        out |= {
            "in-spec": metrics.in_spec_coverage,
            "ceiling": metrics.visibility_ceiling,
            "of-ceiling": metrics.in_spec_of_ceiling,
            "coverage": metrics.coverage_fraction,
            "cycle": metrics.cycle_time_s,
            "a90": found.get("a90_mm"),
            "collisions": float(metrics.collisions_count),
        }
    if cycle_s is not None:
        out["cycle"] = cycle_s
    if arm is not None and (coverage := free_and_flown(arm)) is not None:
        out["arm-cost"] = coverage[0] - coverage[1]
    if robust is not None:
        out |= {"p5": robust.p5, "worst": robust.worst}
    if pod_a90_mm is not None:
        out["pod-a90"] = pod_a90_mm
    return out


def verdict_lines(verdicts: list[Verdict]) -> list[str]:
    """One line per criterion, then the overall verdict."""
    if not verdicts:
        return []
    failed = sum(not v.passed for v in verdicts)
    head = (
        "verdict: pass" if not failed else f"verdict: FAIL ({failed} of {len(verdicts)} criteria)"
    )
    return [head, *(f"  {v.line()}" for v in verdicts)]
