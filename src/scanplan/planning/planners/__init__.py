"""Planners: each turns one Swath into the sensor poses of that pass.

A planner is any object with a `name`, whether it rolls the line (`roll`) and
`plan(part, swath, spec) -> Trajectory`; `pass_path.plan_path` runs one over a whole
Boustrophedon base path.
"""

from __future__ import annotations

import os
from typing import Protocol

from scanplan.core.quantities import ScanSpec, StepLimits
from scanplan.core.trajectory import Trajectory
from scanplan.planning.planners.feedback import FeedbackPlanner
from scanplan.planning.planners.fixed import FixedPlanner
from scanplan.planning.planners.geometric import GeometricPlanner
from scanplan.planning.swaths import Swath
from scanplan.world.part import Part

__all__ = ["FeedbackPlanner", "FixedPlanner", "GeometricPlanner", "Planner", "pass_workers"]


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
