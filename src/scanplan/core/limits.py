"""The ranges a real cell's numbers can have, in one place: lengths, angles, rates, speeds
and counts. Options and files are checked against them at the edge, and a command checks the
size it is about to allocate against its MAX_ before allocating.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pydantic import AfterValidator


@dataclass(frozen=True)
class Limit:
    """A closed range [lo, hi] (an end open on request) with its unit."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return (
            f"{'(' if self.lo_open else '['}{_number(self.lo)}, {_number(self.hi)}"
            f"{')' if self.hi_open else ']'}{unit}"
        )

    def contains(self, value: float) -> bool:
        try:
            value = float(value)
        except (OverflowError, TypeError, ValueError):  # an int of 400 digits, a string
            return False
        if not math.isfinite(value):
            return False
        above_lo = value > self.lo if self.lo_open else value >= self.lo
        below_hi = value < self.hi if self.hi_open else value <= self.hi
        return above_lo and below_hi

    def check(self, value: float, what: str) -> float:
        """`value`, or a ValueError naming `what` (an option or a file's field), the value
        and the range."""
        if not self.contains(value):
            raise ValueError(f"{what} {_number(value)} is not in {self}")
        return value


def _number(value: object) -> str:
    """A value as the message shows it: whole numbers in full up to 16 digits, else %g (an
    int too long for a float by its length)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return repr(value)
    if isinstance(value, int):
        if abs(value) < 10**16:
            return str(value)
        try:
            return f"{float(value):g}"
        except OverflowError:
            return f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    return str(int(value)) if value.is_integer() and abs(value) < 1e16 else f"{value:g}"


# Lengths: a micron to 100 m covers any part, cell or arm; a signed length (an offset of an
# arm's axes) is at most that far either way.
LENGTH_MM = Limit(1e-3, 1e5, "mm")
SIGNED_LENGTH_MM = Limit(-1e5, 1e5, "mm")
# An arm's link from shoulder to elbow (OPW c2): a millimetre at the least.
LINK_MM = Limit(1.0, 1e5, "mm")
# One step of the sensor along a pass (profile spacing, the agent's Δy/Δz limits).
STEP_MM = Limit(1e-3, 1e3, "mm")
# Angles: a step or a tolerance, at most a half turn, at least a thousandth of a degree (no
# controller resolves finer).
ANGLE_DEG = Limit(1e-3, 180.0, "deg")
ANGLE_RAD = Limit(math.radians(1e-3), math.pi, "rad")
# A sensor's datasheet (SPEC §2): what a real line profilometer can have.
WORKING_DISTANCE_MM = Limit(10.0, 5000.0, "mm")
FOV_DEG = Limit(0.1, 170.0, "deg", hi_open=True)
TRIANGULATION_DEG = Limit(1.0, 89.0, "deg")
INCIDENCE_CUTOFF_DEG = Limit(1.0, 90.0, "deg")
MAX_PROFILE_POINTS = 100_000
# A sensor's Z resolution: 0 (none) or from a nanometre up (a denormal one overflows).
Z_RESOLUTION_UM = Limit(1e-3, 1000.0, "µm")
# Sensor noise: a profilometer noisier than a millimetre is none; the speckle's correlation
# length is a sensor step's size.
NOISE_UM = Limit(0.0, 1000.0, "µm")
SPECKLE_SCALE_MM = Limit(1e-3, 1e3, "mm")
# The sensor body box, in the sensor frame: a few metres either way at the most.
SENSOR_BODY_MM = Limit(-5000.0, 5000.0, "mm")
# A trajectory's positions (part frame) and an arm's accelerations.
POSITION_MM = Limit(-1e5, 1e5, "mm")
TCP_ACCEL_MM_S2 = Limit(1e-3, 1e6, "mm/s²")
TURN_SPEED_DEG_S = Limit(1e-3, 1e4, "deg/s")
TURN_ACCEL_DEG_S2 = Limit(1e-3, 1e6, "deg/s²")
# A joint's position or limit: a few turns either way at most.
JOINT_DEG = Limit(-1080.0, 1080.0, "deg")
# A pose given as x,y,z,A,B,C (--part-pose, --tcp): its Euler angles within a turn either way
# (KUKA writes them in (-180, 180]); a TCP's offset from the flange a few metres at most (a
# part's place is a POSITION_MM).
POSE_ANGLE_DEG = Limit(-360.0, 360.0, "deg")
TCP_MM = Limit(-5000.0, 5000.0, "mm")
# In-spec distance tolerance |z_s - W_d|.
TOLERANCE_MM = Limit(1e-3, 1e3, "mm")
# An orientation error a point may have (the in-spec angle tolerance, the reward's α_max):
# past 90° the beam meets the surface from behind.
ORIENTATION_ERROR_DEG = Limit(1e-3, 90.0, "deg")
# How far the sensor body stays from the part: no further than the longest working distance.
CLEARANCE_MM = Limit(0.0, WORKING_DISTANCE_MM.hi, "mm")
# A reward term's weight (the paper's are 1/3 each; they need not sum to 1).
REWARD_WEIGHT = Limit(0.0, 1e3)
# A pass line's length: a part of at most 100 m.
PASS_LENGTH_MM = Limit(0.0, LENGTH_MM.hi, "mm")
# Line profilometers run from a few Hz to some tens of kHz.
PROFILE_RATE_HZ = Limit(1e-1, 1e5, "Hz")
# A TCP's speed: no arm moves its tool faster than 10 m/s; a scan (rate x spacing) no faster
# than a few m/s.
SPEED_MM_S = Limit(1e-3, 1e4, "mm/s")
MAX_SCAN_SPEED_MM_S = 5_000.0
# A cycle or a planning time: at most about 30 years.
DURATION_S = Limit(0.0, 1e9, "s")
# A defect's size (its depth) and the call threshold in σ of the sensor noise.
DEFECT_SIZE_MM = Limit(1e-4, 100.0, "mm")
K_SIGMA = Limit(0.0, 1000.0, "σ", lo_open=True)
# The initial mean Δy action of a policy (actions are in [-1, 1]).
ACTION = Limit(-1.0, 1.0)
# Training (`scanplan train`, a sweep's grid, policy.json): R_D's scale, the depth error it
# charges -1: under a tenth of a millimetre every depth error a step makes (Δz up to 1 mm)
# costs -1, a saturated reward that teaches nothing. PPO's numbers as SB3 takes them: a
# learning rate under 1e-8 never moves the weights; a discount under 0.5 looks less than
# two steps ahead; a clip range under 1 % never lets the policy change. An initial log std
# above 2 (σ ≈ 7 on actions in [-1, 1]) clips every action to a bound.
REWARD_DISTANCE_SCALE_MM = Limit(0.1, 1e4, "mm")
LEARNING_RATE = Limit(1e-8, 1.0)
DISCOUNT = Limit(0.5, 1.0)
CLIP_RANGE = Limit(0.01, 1.0)
LOG_STD = Limit(-20.0, 2.0)
# A perturbation's σ (`--perturb`): a placement, path or as-built error of a metre or a half
# turn is a part in another place, not an error; zero leaves its term out. The part's scale
# error: 10 % is a part of another size already (and keeps every draw's scale > 0).
PERTURB_MM = Limit(0.0, 1000.0, "mm")
PERTURB_DEG = Limit(0.0, 180.0, "deg")
PERTURB_SCALE_PERCENT = Limit(0.0, 10.0, "%")

# Counts: what a command may allocate before it starts.
MAX_PASSES = 10_000  # passes of one view's raster
MAX_PLACEMENTS = 1_000_000  # candidate placements `place` ranks
MAX_TIMESTEPS = 10**10  # PPO steps of one run
MAX_BC_SAMPLES = 10**7  # states behaviour cloning stores (a few hundred MB)
MAX_SEED = 2**32 - 1  # numpy's and torch's seeds
MAX_RUNS = 10_000  # runs of one sweep (seeds x grid)
MAX_DEFECTS = 100_000  # defects of one POD run (trials x per trial)
# Fixtures of one cell: a cell holds a few clamps, tens at most. Each is a mesh with its own
# Embree scene and collision model; a thousand live scenes crash the process.
MAX_FIXTURES = 100


class TooLarge(ValueError):
    """A size over its MAX_: a mistake of the user's that no fallback (another view, another
    candidate) may swallow."""


def check_count(count: int, limit: int, what: str, hint: str = "") -> int:
    """`count`, or a ValueError saying what would be too many (before it is allocated)."""
    if count > limit:
        more = f"; {hint}" if hint else ""
        shown = f"{count:,}" if count < 10**15 else f"{float(count):.3g}"
        raise TooLarge(f"{what}: {shown} is more than the {limit:,} allowed{more}")
    return count


# Sizes a file may announce before it is read whole.
MAX_VIEWS = 10_000  # view records of one trajectory (a plan has tens)
MAX_POSES = 10_000_000  # poses of one trajectory (a 1 GiB CSV holds about this many)
MAX_TRIANGLES = 20_000_000  # a part's triangles (about 3 GB once loaded)
# Rays one `scan` or `demo` casts (poses x points per profile): about a day on this machine.
MAX_RAYS = 10**11
# Points a point cloud holds in memory before it is written (64 bytes each: ~10 GB).
MAX_CLOUD_POINTS = 150_000_000
MAX_POLICY_PARAMS = 100_000_000  # an actor's weights (400 MB of float32; ours has 5 000)


def in_range(limit: Limit, or_zero: bool = False) -> Any:
    """The pydantic check of a number in `limit` (or 0, on request), as
    `Annotated[float, in_range(LENGTH_MM)]`: its message names the value and the range
    ("1e+308 is not in [-100000, 100000] mm"); the loader adds the file and the field."""

    def check(value: float) -> float:
        if not (limit.contains(value) or (or_zero and value == 0)):
            raise ValueError(f"{_number(value)} is not {'0 or ' if or_zero else ''}in {limit}")
        return value

    return AfterValidator(check)
