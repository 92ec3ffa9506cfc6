"""What the view choice may spend (`ViewBudget`: views planned, and a wall-clock limit only
where the user asks for one) and what it has spent (`Spent`): counted in work, so the same
inputs choose the same views on a busy machine and a quiet one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from scanplan.core.quantities import VIEW_CHOICE_CANDIDATES


@dataclass(frozen=True)
class ViewBudget:
    """How much the view choice may do: `candidates` views planned (work, the same on any
    machine), and a wall-clock limit in `seconds` only where the user asks for one."""

    candidates: int = VIEW_CHOICE_CANDIDATES
    seconds: float | None = None

    def __post_init__(self) -> None:
        if self.candidates < 1:
            raise ValueError(f"--view-candidates must be at least 1, got {self.candidates}")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"--view-seconds must be a number of seconds > 0, got {self.seconds}")

    def said(self) -> str:
        """How the plan's note names the budget that stopped the choice."""
        limit = f"{self.candidates} candidate views"
        return limit + (f" or {self.seconds:g} s" if self.seconds is not None else "")


class Spent:
    """What the view choice has spent of its `budget`: candidates taken, and the clock."""

    def __init__(self, budget: ViewBudget) -> None:
        self.budget = budget
        self.deadline = None if budget.seconds is None else time.perf_counter() + budget.seconds
        self.taken = 0  # candidates whose plan the choice has taken: the work it counts
        self.timed_out = False

    def out_of_work(self) -> bool:
        """Whether the candidates the budget allows are all taken (said as out of time)."""
        self.timed_out = self.timed_out or self.taken >= self.budget.candidates
        return self.timed_out

    def out_of_time(self) -> bool:
        # Asked only where another candidate would be planned: True means one was not.
        # Counted in candidates taken, not asked of the workers (how far they plan ahead
        # depends on the cores), so the same views on any machine and any load.
        self.timed_out = self.timed_out or self.taken >= self.budget.candidates
        self.timed_out = self.timed_out or (
            self.deadline is not None and time.perf_counter() > self.deadline
        )
        return self.timed_out
