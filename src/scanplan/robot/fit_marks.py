"""What a fit (`robot.fit`) knows about each pose of the plan it is fitting, round after
round: kept or given up and why, the pass it is in now, how the arm enters it; and the
poses it puts in to go round what the arm cannot fly (`FitMarks.with_ways`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from scanplan.core.trajectory import Trajectory, half_turns, lead_tops
from scanplan.robot.straight_moves import Way


def entries_of(traj: Trajectory, raised: np.ndarray) -> np.ndarray:
    """(n,) bool: where the path and each of its passes are entered by a joint move: its
    first pose, and each pass's first pose or, where `raised` (n,) marks that pose, the top
    of the move leading into it (`lead_tops`); and each pose the sensor comes to turned
    about half a turn from the pose before (`half_turns`: a pass turned beside its move)."""
    top = lead_tops(traj)
    first = np.flatnonzero(top >= 0)
    entry = np.zeros(len(traj), bool)
    entry[np.where(raised[first], top[first], first)] = True
    entry[:1] = True
    return entry | half_turns(traj)


def renumbered_passes(
    traj: Trajectory, keep: np.ndarray, swath: np.ndarray, cut: np.ndarray
) -> np.ndarray:
    """Swath indices in order, consecutive over the kept poses: a new one wherever a pass
    resumes after given-up poses or at a cut, so pieces of one pass become passes."""
    index = np.flatnonzero(keep)
    new_pass = np.zeros(len(index), bool)
    if len(index):
        same = swath[index[1:]] == swath[index[:-1]]
        gap = (np.diff(index) > 1) & traj.scanning[index[1:]]
        new_pass[1:] = ~same | gap
    new_pass |= cut[index]
    out = swath.copy()
    out[index] = int(swath[index[0]]) + np.cumsum(new_pass) - int(new_pass[0]) if len(index) else 0
    return out


@dataclass
class FitMarks:
    """Per pose of the fit's plan: kept; why given up (into `CAUSES`, -1: not); its pass,
    renumbered over the kept; its pass flown the other way (`flown_back`); a pass's first
    entered at the top of its move (`lifted`), or whose move down flips (`lowered`);
    entered by a joint move after poses given up or from a pose put in (`resumed`);
    reached by a straight move down from a pose put in above it, so not entered by a joint
    move though a pass starts there (`descended`); how many times a joint move into it was
    lifted (`lifts`, a pose a lift put in counting as the pose it leads to)."""

    keep: np.ndarray
    cause: np.ndarray
    swath: np.ndarray
    flipped: np.ndarray
    raised: np.ndarray
    low: np.ndarray
    resumed: np.ndarray
    descended: np.ndarray
    lifts: np.ndarray

    @classmethod
    def of(cls, traj: Trajectory) -> FitMarks:
        n = len(traj)
        keep, cause, swath = np.ones(n, bool), np.full(n, -1), traj.swath.copy()
        flipped, raised, low, resumed, descended = (np.zeros(n, bool) for _ in range(5))
        return cls(keep, cause, swath, flipped, raised, low, resumed, descended, np.zeros(n, int))

    def entry(self, current: Trajectory) -> np.ndarray:
        """(len(current),) where the arm enters `current` (the kept poses) by a joint move."""
        keep = self.keep
        return (entries_of(current, self.raised[keep]) | self.resumed[keep]) & ~self.descended[keep]

    def give_up(
        self, traj: Trajectory, index: np.ndarray, why: np.ndarray, cuts: np.ndarray
    ) -> int:
        """The kept poses (at `index`) with a cause in `why` (>= 0) given up, and passes cut
        before the kept poses `cuts` (flips, joints swinging): a pass goes on after a gap or
        a cut as a new pass, the arm reconfiguring between. Returns how many were cut."""
        bad = np.flatnonzero(why >= 0)
        self.keep[index[bad]] = False
        self.cause[index[bad]] = why[bad]
        cut = np.zeros(len(traj), bool)
        cut[index[cuts]] = True
        self.swath = renumbered_passes(traj, self.keep, self.swath, cut)
        return len(cuts)

    def with_ways(self, traj: Trajectory, ways: dict[int, Way]) -> tuple[Trajectory, FitMarks]:
        """`traj` with the poses of `ways` ({pose: the way the arm goes to it}) put in before
        their pose, in its pass (with its external axes' values), and these marks grown to
        match: those poses kept, given up for nothing, entered by a joint move as their way
        says and lifted as often as the pose after; the pose after entered by one as it says,
        and, where a joint move reaches a pose put in and a straight one it, descended."""
        if not ways:
            return traj, self
        at = np.array(sorted(ways))
        count = np.array([len(ways[i].poses) for i in at])
        slots = np.repeat(at, count)  # where each pose put in goes (before its pose)
        added = slots + np.arange(len(slots))  # where those poses are then
        after = at + np.cumsum(count)  # and their poses
        grown = {f.name: np.insert(getattr(self, f.name), slots, False) for f in fields(self)}
        grown["keep"][added] = True
        grown["cause"] = np.insert(self.cause, slots, -1)
        grown["swath"] = np.insert(self.swath, slots, self.swath[slots])
        grown["lifts"] = np.insert(self.lifts, slots, self.lifts[slots])
        grown["resumed"][added] = np.concatenate([ways[i].jointed for i in at])
        end_jointed = np.array([ways[i].end_jointed for i in at])
        grown["resumed"][after] = end_jointed
        grown["descended"][after] = ~end_jointed & [ways[i].jointed.any() for i in at]
        poses = np.insert(traj.poses, slots, np.concatenate([ways[i].poses for i in at]), axis=0)
        external = traj.external
        if external is not None:
            external = np.insert(external, slots, external[slots], axis=0)
        return replace(
            traj,
            poses=poses,
            swath=np.insert(traj.swath, slots, traj.swath[slots]),
            scanning=np.insert(traj.scanning, slots, False),
            external=external,
        ), FitMarks(**grown)
