"""The ranges a real cell's numbers can have, in one place: lengths, angles, rates, speeds
and counts. Options and files are checked against them at the edge, and a command checks the
size it is about to allocate against its MAX_ before allocating.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Limit:
    """A closed range [lo, hi] (an open lower end on request) with its unit."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]{unit}"

    def contains(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        above_lo = value > self.lo if self.lo_open else value >= self.lo
        return above_lo and value <= self.hi

    def check(self, value: float, what: str) -> float:
        """`value`, or a ValueError naming `what` (an option or a file's field), the value
        and the range."""
        if not self.contains(value):
            raise ValueError(f"{what} {value:g} is not in {self}")
        return value


# Lengths: a micron to 100 m covers any part, cell or arm; a signed length (an offset of an
# arm's axes) is at most that far either way.
LENGTH_MM = Limit(1e-3, 1e5, "mm")
SIGNED_LENGTH_MM = Limit(-1e5, 1e5, "mm")
# An arm's link from shoulder to elbow (OPW c2): a millimetre at the least.
LINK_MM = Limit(1.0, 1e5, "mm")
# One step of the sensor along a pass (profile spacing, the agent's Δy/Δz limits).
STEP_MM = Limit(1e-3, 1e3, "mm")
# Angles: a step or a tolerance, at most a half turn.
ANGLE_DEG = Limit(0.0, 180.0, "deg", lo_open=True)
ANGLE_RAD = Limit(0.0, math.pi, "rad", lo_open=True)
# A joint's position or limit: a few turns either way at most.
JOINT_DEG = Limit(-1080.0, 1080.0, "deg")
# In-spec distance tolerance |z_s - W_d|.
TOLERANCE_MM = Limit(1e-3, 1e3, "mm")
# Line profilometers run from a few Hz to some tens of kHz.
PROFILE_RATE_HZ = Limit(1e-1, 1e5, "Hz")
# A TCP's speed: no arm moves its tool faster than 10 m/s; a scan (rate x spacing) no faster
# than a few m/s.
SPEED_MM_S = Limit(1e-3, 1e4, "mm/s")
MAX_SCAN_SPEED_MM_S = 5_000.0
# A defect's size (its depth) and the call threshold in σ of the sensor noise.
DEFECT_SIZE_MM = Limit(1e-4, 100.0, "mm")
K_SIGMA = Limit(0.0, 1000.0, "σ", lo_open=True)
# The initial mean Δy action of a policy (actions are in [-1, 1]).
ACTION = Limit(-1.0, 1.0)

# Counts: what a command may allocate before it starts.
MAX_PASSES = 10_000  # passes of one view's raster
MAX_PLACEMENTS = 1_000_000  # candidate placements `place` ranks
MAX_TIMESTEPS = 10**10  # PPO steps of one run
MAX_BC_SAMPLES = 10**7  # states behaviour cloning stores (a few hundred MB)
MAX_SEED = 2**32 - 1  # numpy's and torch's seeds
MAX_RUNS = 10_000  # runs of one sweep (seeds x grid)
MAX_DEFECTS = 100_000  # defects of one POD run (trials x per trial)


class TooLarge(ValueError):
    """A size over its MAX_: a mistake of the user's that no fallback (another view, another
    candidate) may swallow."""


def check_count(count: int, limit: int, what: str, hint: str = "") -> int:
    """`count`, or a ValueError saying what would be too many (before it is allocated)."""
    if count > limit:
        more = f"; {hint}" if hint else ""
        raise TooLarge(f"{what}: {count:,} is more than the {limit:,} allowed{more}")
    return count
