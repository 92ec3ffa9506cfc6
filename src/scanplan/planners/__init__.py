"""Planners: each turns one Swath into the sensor poses of that pass.

A planner is any object with a `name`, whether it rolls the line (`roll`) and
`plan(part, swath, spec) -> Trajectory`; `pipeline.plan_path` runs one over a whole
Boustrophedon base path.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Protocol

from scanplan.part import Part
from scanplan.planners.feedback import FeedbackPlanner
from scanplan.planners.fixed import FixedPlanner
from scanplan.planners.geometric import GeometricPlanner
from scanplan.quantities import ScanSpec, StepLimits
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory


class Planner(Protocol):
    """A pass planner. Two optional hooks `plan_path` looks for: `plan_passes(part, swaths,
    spec)`, every pass in one call (the closed loop steps them in lockstep), and
    `batched_passes = True`, passes planned on a thread per core (`pass_workers`)."""

    @property
    def name(self) -> str: ...

    @property
    def roll(self) -> bool:
        """Whether the planner tilts the line across the pass (beyond the paper)."""
        ...

    @property
    def limits(self) -> StepLimits:
        """The per-step limits its passes keep (recorded in the plan's context)."""
        ...

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        """The scanning poses of one pass (all flagged scanning, swath = swath.index)."""
        ...


def pass_workers(planner: Planner, passes: int) -> int:
    """Threads to plan passes on: one per core for a planner that measures a whole pass per
    ray cast (`batched_passes`, the geometric planner; the ray casts and much of numpy
    release the GIL), else one. (The closed loop steps all passes together instead,
    `plan_passes`.)"""
    batched = bool(getattr(planner, "batched_passes", False))
    return max(1, min(passes, os.cpu_count() or 1)) if batched else 1


PLANNERS = ("fixed", "feedback", "geometric", "rl")


def make_planner(name: str, policy: str | os.PathLike | None = None, roll: bool = True) -> Planner:
    """The planner called `name`; `rl` loads a policy directory (None: the shipped one) and
    rolls if the policy is a v1 one. roll=False: the paper's pitch-only geometric and
    feedback planners."""
    if name == "fixed":
        return FixedPlanner()
    if name == "feedback":
        return FeedbackPlanner(roll=roll)
    if name == "geometric":
        return GeometricPlanner.with_roll() if roll else GeometricPlanner()
    if name == "rl":
        # Deferred: the rl planner loads torch, which no other planner needs.
        from scanplan.planners.rl import RLPlanner

        return RLPlanner.from_file(None if policy is None else Path(policy))
    raise ValueError(f"unknown planner {name!r}; use one of {', '.join(PLANNERS)}")
