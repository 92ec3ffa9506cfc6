"""Every planner by name: the model-based ones and the trained policy's."""

from __future__ import annotations

import os
from pathlib import Path

from scanplan.planning.planners import FeedbackPlanner, FixedPlanner, GeometricPlanner, Planner

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
        from scanplan.rl.planner import RLPlanner

        return RLPlanner.from_file(None if policy is None else Path(policy))
    raise ValueError(f"unknown planner {name!r}; use one of {', '.join(PLANNERS)}")
