"""Planners: each turns one Swath into the sensor poses of that pass.

A planner is any object with a `name` and `plan(part, swath, spec) -> Trajectory`;
`plan_path` runs one over a whole Boustrophedon base path and adds the lift-off transitions.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Protocol

import numpy as np

from scanplan.part import Part
from scanplan.quantities import ScanSpec
from scanplan.swaths import Swath, transition_poses
from scanplan.trajectory import Trajectory


class Planner(Protocol):
    @property
    def name(self) -> str: ...

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        """The scanning poses of one pass (all flagged scanning, swath = swath.index)."""
        ...


PLANNERS = ("fixed", "feedback", "geometric", "rl")


def make_planner(name: str, policy: str | os.PathLike | None = None) -> Planner:
    """The planner called `name`; `rl` loads a policy directory (None: the shipped one)."""
    if name == "fixed":
        from scanplan.planners.fixed import FixedPlanner

        return FixedPlanner()
    if name == "feedback":
        from scanplan.planners.feedback import FeedbackPlanner

        return FeedbackPlanner()
    if name == "geometric":
        from scanplan.planners.geometric import GeometricPlanner

        return GeometricPlanner()
    if name == "rl":
        from scanplan.planners.rl import RLPlanner

        return RLPlanner.from_file(None if policy is None else Path(policy))
    raise ValueError(f"unknown planner {name!r}; use one of {', '.join(PLANNERS)}")


def plan_path(part: Part, spec: ScanSpec, planner: Planner, swaths: list[Swath]) -> Trajectory:
    """All passes in snake order, joined by non-scanning lift-off transitions."""
    if not swaths:
        raise ValueError("no swath to plan")
    start = time.perf_counter()
    pieces: list[Trajectory] = []
    for i, swath in enumerate(swaths):
        if i > 0:
            moves = transition_poses(swaths[i - 1], swath)
            pieces.append(
                Trajectory(moves, np.full(len(moves), swath.index), np.zeros(len(moves), bool))
            )
        pieces.append(planner.plan(part, swath, spec))
    traj = Trajectory.concatenate(pieces, planner=planner.name)
    return Trajectory(
        traj.poses,
        traj.swath,
        traj.scanning,
        plan_time_s=time.perf_counter() - start,
        planner=planner.name,
        meta=traj.meta,
    )
