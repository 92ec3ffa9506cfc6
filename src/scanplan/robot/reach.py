"""Can an arm follow a flange path? Unreachable poses, joint limits, singularities, flips.

Works for any `Robot`; the path is `T_base_flange` (n, 4, 4) in mm, e.g. from
`scanplan.robot.export.flange_poses`.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scanplan.robot.base import Robot, wrap
from scanplan.robot.nearest_joints import (
    fit_limits,
    follow,
    limit_margin,
    nearest_solution,
    next_within,
)
from scanplan.robot.pass_branches import CellView, by_flown, flown_count
from scanplan.robot.presets import get_robot

# A joint turning more than this between consecutive poses of a pass is a jump: no longer
# the branch the controller follows there (`check_reach`).
JUMP_DEG = 30.0


def same_pass(n: int, swath: np.ndarray | None, scanning: np.ndarray | None) -> np.ndarray:
    """(n - 1,) True where poses i and i+1 belong to one scanning pass (all, without info)."""
    if swath is None or scanning is None:
        return np.ones(max(n - 1, 0), dtype=bool)
    swath, scanning = np.asarray(swath), np.asarray(scanning, dtype=bool)
    if len(swath) != n or len(scanning) != n:
        raise ValueError(f"{n} poses but {len(swath)} swath and {len(scanning)} scanning flags")
    return scanning[1:] & scanning[:-1] & (swath[1:] == swath[:-1])


def pass_starts(swath: np.ndarray, scanning: np.ndarray) -> np.ndarray:
    """(n,) True at each pass's first pose: where a program enters the pass by a joint move."""
    scanning = np.asarray(scanning, dtype=bool)
    return scanning & ~np.r_[False, same_pass(len(scanning), swath, scanning)]


@dataclass(frozen=True)
class ReachReport:
    """Whether an arm can follow a flange path, branch by branch.

    joints: (n, 6) rad along the followed IK branch (closest solution to the previous pose),
            NaN where unreachable or beyond the joint limits. Index arrays are pose indices;
            a jump or flip at i is between poses i-1 and i. Flips count within a pass and
            on the linear move down into it from where it is entered: no controller changes
            configuration in a linear move.
    margins: (n, 3) |wrist|, |elbow| (sines) and shoulder (mm) singularity distances;
    limit_margin_rad: (n,) to the nearest joint limit. NaN where `joints` is.
    """

    model: str
    joints: np.ndarray
    unreachable: np.ndarray
    limit_violations: np.ndarray
    wrist_singular: np.ndarray
    elbow_singular: np.ndarray
    shoulder_singular: np.ndarray
    wrist_flips: np.ndarray
    config_flips: np.ndarray
    joint_jumps: np.ndarray
    jump_deg: float
    margins: np.ndarray
    limit_margin_rad: np.ndarray
    # The joint jumps between poses of one pass (the others are joint moves between passes).
    pass_jumps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def near_singular(self) -> np.ndarray:
        return np.union1d(
            np.union1d(self.wrist_singular, self.elbow_singular), self.shoulder_singular
        )

    @property
    def reachable(self) -> bool:
        """Every pose reachable inside the joint limits, no configuration flip in a pass
        or on the move into it."""
        return not (len(self.unreachable) or len(self.limit_violations) or len(self.config_flips))

    @property
    def ok(self) -> bool:
        return self.reachable and not (len(self.near_singular) or len(self.joint_jumps))

    def first_problem(self) -> tuple[int, str]:
        """(pose index, what) of the first pose that stops the arm: unreachable, beyond the
        joint limits or flipping configuration within a pass; (-1, '') if none does."""
        found = [
            (int(a[0]), what)
            for a, what in (
                (self.unreachable, "is unreachable"),
                (self.limit_violations, "is beyond the joint limits"),
                (self.config_flips, "flips the arm's configuration in a linear move"),
            )
            if len(a)
        ]
        return min(found) if found else (-1, "")

    def worst_margins(self) -> dict[str, float]:
        """The smallest margin along the path: joint limit (deg), wrist and elbow (deg from
        the singular configuration), shoulder (mm); NaN where no pose is reachable."""
        if np.isnan(self.limit_margin_rad).all():
            return dict.fromkeys(("limit_deg", "wrist_deg", "elbow_deg", "shoulder_mm"), np.nan)
        m = np.nanmin(self.margins, axis=0)
        return {
            "limit_deg": float(np.degrees(np.nanmin(self.limit_margin_rad))),
            "wrist_deg": float(np.degrees(np.arcsin(min(m[0], 1.0)))),
            "elbow_deg": float(np.degrees(np.arcsin(min(m[1], 1.0)))),
            "shoulder_mm": float(m[2]),
        }

    def summary(self) -> str:
        return (
            f"{self.model}: {len(self.joints)} poses, {len(self.unreachable)} unreachable, "
            f"{len(self.limit_violations)} beyond joint limits, "
            f"{len(self.near_singular)} near-singular (wrist {len(self.wrist_singular)}, "
            f"elbow {len(self.elbow_singular)}, shoulder {len(self.shoulder_singular)}), "
            f"{len(self.config_flips)} configuration flips in a linear move "
            f"({len(self.wrist_flips)} wrist), {len(self.joint_jumps)} joint jumps "
            f"> {self.jump_deg:g}° ({len(self.pass_jumps)} inside a pass)"
        )


def _runs_linked(
    entry: np.ndarray, swath: np.ndarray | None, scanning: np.ndarray | None, linked: np.ndarray
) -> np.ndarray:
    """(n - 1,) True where poses i and i+1 are flown on one branch: within a pass (`linked`),
    or from a pass's `entry` pose on the move leading into it (the same swath index) to
    its first pose."""
    if swath is None or scanning is None:
        return linked
    n = len(entry)
    if entry.shape != (n,) or len(swath) != n:
        raise ValueError(f"{len(swath)} poses but {entry.shape} entry flags")
    swath, scanning = np.asarray(swath), np.asarray(scanning, dtype=bool)
    # Poses after an entry up to its pass's first: in a run of moves of one swath index,
    # those at or after an entry among them.
    moving = ~scanning
    fresh = moving & np.r_[True, scanning[:-1] | (swath[1:] != swath[:-1])]
    seen = np.cumsum(entry & moving)
    before = seen - (entry & moving)  # entries before each pose
    at_run = np.maximum.accumulate(np.where(fresh, np.arange(n), 0))
    lead = moving & (seen > before[at_run])
    return linked | (lead[:-1] & (lead[1:] | scanning[1:]) & ~entry[1:] & (swath[1:] == swath[:-1]))


def _run_ends(linked: np.ndarray) -> np.ndarray:
    """(n,) one past the last pose of the pass (run of `linked` poses) each pose is in."""
    n = len(linked) + 1
    last = np.flatnonzero(np.r_[~linked, True])  # a run's last pose
    return last[np.searchsorted(last, np.arange(n))] + 1


def _pass_start(
    arm: Robot,
    solutions: np.ndarray,
    limits: np.ndarray,
    prev: np.ndarray | None,
    tol: np.ndarray,
    jump_deg: float,
    cell: CellView | None = None,
    at: tuple[int, int] = (0, -1),
) -> np.ndarray | None:
    """The joints to enter a pass with, from its IK `solutions` (m, 8, 6): on the branch
    that flies the most poses from the first one on without leaving the reach or the joint
    limits, changing configuration (a sign of `singularity_terms`) or turning a joint more
    than `jump_deg` between poses, nor, with a `cell`, bringing a link into it; among those
    that fly as many, the one nearest `prev` (the joint move in; with a cell, the most
    flown whose move in keeps the links clear, if any), or without one the farthest from
    singularities and limits. at: (this pass's first pose, `prev`'s pose) for the cell.
    None where the first pose has no solution within the limits."""
    first, inside = fit_limits(solutions[0], limits)
    ok = inside & ~np.isnan(first).any(axis=1)
    if not ok.any():
        return None
    if prev is not None:  # each branch turned the way nearest the previous joints, if legal
        near, inside = fit_limits(prev + wrap(solutions[0] - prev), limits)
        first = np.where((inside & ~np.isnan(near).any(axis=1))[:, None], near, first)
    branches = np.flatnonzero(ok)
    path = solutions[:, branches]  # (m, b, 6)
    # Each branch followed continuously (unwrapped), from the first pose's turn.
    path = first[branches] + np.cumsum(
        np.r_[np.zeros((1, len(branches), 6)), wrap(np.diff(path, axis=0))], axis=0
    )
    lo, hi = limits[:, 0] - 1e-12, limits[:, 1] + 1e-12
    held = ((path >= lo) & (path <= hi)).all(axis=2)  # NaN: not held
    step = np.abs(np.diff(path, axis=0)).max(axis=2)
    held[1:] &= step <= np.radians(jump_deg)
    signs = np.signbit(arm.singularity_terms(np.nan_to_num(path)))
    held &= (signs == signs[0]).all(axis=2)
    if cell is None:
        flown = flown_count(held)
        best = branches[flown == flown.max()]
    else:  # the links checked only for the branches the choice reaches, most flown first
        dist = np.zeros(len(branches)) if prev is None else ((first[branches] - prev) ** 2).sum(1)
        order = by_flown(held, path, dist, cell, at[0])
        k0, most = next(order)
        if prev is not None:  # the most flown whose joint move in keeps the links clear
            for k, count in itertools.chain([(k0, most)], order):
                if count == 0:
                    break
                if cell.clear_move(at[1], prev, at[0], first[branches[k]]):
                    return first[branches[k]]
            return first[branches[k0]]  # none: the most flown, nearest the joints before
        tied = itertools.takewhile(lambda kc: kc[1] == most, order)
        best = branches[np.sort([k0, *(k for k, _ in tied)])]
    cand = first[best]
    if prev is not None:
        return cand[np.argmin(((cand - prev) ** 2).sum(axis=1))]
    terms = np.abs(arm.singularity_terms(cand)) / tol
    score = np.minimum(terms.min(axis=1), limit_margin(cand, limits) / np.radians(5))
    # Rounded: branches that tie (a margin set by the same joint limit) must not be told
    # apart by a pose's last digits, or a plan read back from its file (to 1e-6 mm) is
    # checked on another branch than it was fitted on.
    return cand[np.argmax(np.round(score, 4))]


def check_reach(
    T_base_flange: np.ndarray,
    robot: str | Path | Robot = "ur5e",
    q_start: np.ndarray | None = None,
    swath: np.ndarray | None = None,
    scanning: np.ndarray | None = None,
    wrist_tol: float = np.sin(np.radians(5.0)),
    elbow_tol: float = np.sin(np.radians(5.0)),
    shoulder_tol_mm: float = 20.0,
    jump_deg: float = JUMP_DEG,
    cell: CellView | None = None,
    entries: Mapping[int, np.ndarray] | None = None,
    entry: np.ndarray | None = None,
    restarts: np.ndarray | None = None,
) -> ReachReport:
    """Follow the path through IK and report what would stop or upset a real arm.

    Each pass is entered on the branch that flies the most of it (`_pass_start`; the first
    reachable pose on the solution closest to `q_start` if given), with the arm's links
    clear of the `cell` along it and on the joint move into it if a cell is given; or at
    the solution nearest the joints `entries` records for its first pose (the
    configurations a fit chose, as its plan records them). A joint move's poses, each a
    pass of its own, take the branch nearest the joints before. entry: (n,) where each pass
    is entered (`trajectory.pass_entries`: the top of the move leading into it, the move's
    poses after it flown on the pass's configuration); None: at its first pose. restarts:
    (n,) True where another path starts (on a pass of its own), followed as if checked
    alone (no joints before it; `q_start` is the first path's). Each next pose of a pass
    takes the in-limit solution closest to the previous one, as a controller executing
    linear moves would. A configuration flip is a sign change of a singularity term
    (wrist, elbow, shoulder) between consecutive poses of one pass (`swath`, `scanning`;
    without them the whole path is one pass). A jump is any joint turning more than
    `jump_deg` between consecutive poses.
    """
    arm = get_robot(robot)
    poses = np.asarray(T_base_flange, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"flange poses must be (n, 4, 4), got {poses.shape}")
    n = len(poses)
    linked = same_pass(n, swath, scanning)
    limits = arm.joint_limits
    solutions = arm.inverse(poses)
    exists = ~np.isnan(solutions).any(axis=2)
    tol = np.array([wrist_tol, elbow_tol, shoulder_tol_mm])
    joints = np.full((n, 6), np.nan)
    prev: np.ndarray | None = None if q_start is None else np.asarray(q_start, dtype=float)
    # A pass's configuration is chosen over the whole pass, where a program enters it by a
    # joint move: the branch that flies most of it from its start (or from its lead-in's).
    # Jumps count within a pass only (`linked`); flips also on the linear move down into a
    # pass from where it is entered (`followed`): a controller cannot flip in a linear move.
    followed = (
        linked if entry is None else _runs_linked(np.asarray(entry, bool), swath, scanning, linked)
    )
    pinned = q_start is not None
    last = -1  # the pose `prev` is the joints of (-1: none, or `q_start`)
    path_of = np.zeros(n, int) if restarts is None else np.cumsum(restarts)
    prev_path = path_of[0] if n else 0  # the path `prev` belongs to
    entered, end, recorded, alone, stops = _runs(followed, path_of, entries)
    # Sequential, but a pass or a move follows one branch: a run checked at once (`follow`).
    i = 0
    while i < n:
        if prev is not None and path_of[i] != prev_path:  # another path: none before it
            prev, last, pinned = None, -1, False
        if not exists[i].any():
            i += 1
            continue
        prev_path = path_of[i]
        by_move = bool(alone[i]) and not pinned
        if prev is None or (entered[i] and not pinned and not by_move):
            if recorded[i]:  # the configuration recorded
                at = np.asarray((entries or {})[i])[None]
                found = nearest_solution(solutions[i : i + 1], limits, at)
                start = None if found is None else found[1]
            else:
                start = _pass_start(
                    arm, solutions[i : end[i]], limits, prev, tol, jump_deg, cell, (i, last)
                )
            if start is None:  # none within the limits: on to the next pose with one
                hi = end[i] if prev is None else i + 1  # with joints before: as in a pass
                i = next_within(solutions, limits, None, i + 1, hi)
                continue
            prev, last = start, i
            joints[i] = prev
            i += 1
            continue
        # In a pass or a move, or the first pose after `q_start`: the nearest in-limit joints.
        pinned = False
        nearest = nearest_solution(solutions[i : i + 1], limits, prev[None])
        if nearest is None:
            i = next_within(solutions, limits, prev, i + 1, end[i])
            continue
        branch, prev = nearest
        joints[i], last = prev, i
        stop = stops[np.searchsorted(stops, i + 1)] if by_move else end[i]
        ran = follow(solutions[i + 1 : stop], limits, prev, branch)
        if len(ran):
            joints[i + 1 : i + 1 + len(ran)] = ran
            prev, last = ran[-1], i + len(ran)
        i += 1 + len(ran)
    return _report(arm, joints, exists, linked, tol, jump_deg, followed)


def _runs(
    followed: np.ndarray, path_of: np.ndarray, entries: Mapping[int, np.ndarray] | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The runs of poses flown on one branch (`followed` (n - 1,) links them) as
    `check_reach` steps them: (n,) where each run is entered, (n,) one past its last pose
    (`_run_ends`), (n,) the poses whose entry `entries` records, (n,) the poses flown alone,
    each a run of its own (a joint move's), their entry not recorded; and the sorted indices
    (then n) a stretch of those followed at once stops at: each pose not flown alone or
    starting another path (`path_of` changes)."""
    n = len(followed) + 1
    entered, end = np.r_[True, ~followed], _run_ends(followed)
    recorded = np.zeros(n, bool)
    recorded[[k for k in (entries or {}) if 0 <= k < n]] = True
    alone = entered & (end == np.arange(1, n + 1)) & ~recorded
    starts_path = path_of != np.r_[-1, path_of[:-1]]
    return entered, end, recorded, alone, np.r_[np.flatnonzero(~alone | starts_path), n]


def _report(
    arm: Robot,
    joints: np.ndarray,
    exists: np.ndarray,
    linked: np.ndarray,
    tol: np.ndarray,
    jump_deg: float,
    followed: np.ndarray,
) -> ReachReport:
    """What the joints `check_reach` followed say: poses without a solution (`exists` (n, 8)
    none) or beyond the limits, near-singular ones (`tol`: wrist, elbow, shoulder), flips
    where the arm flies linearly (`followed`: a pass and the move into it) and jumps, those
    within a pass (`linked`) apart."""
    limits = arm.joint_limits
    wrist_tol, elbow_tol, shoulder_tol_mm = tol
    reachable = ~np.isnan(joints).any(axis=1)
    terms = arm.singularity_terms(joints)
    margins = np.abs(terms)
    idx = np.flatnonzero
    step = np.abs(np.diff(joints, axis=0))  # NaN across unreachable poses: never flagged
    jumps = np.nanmax(np.where(np.isnan(step), 0.0, step), axis=1) > np.radians(jump_deg)
    config = np.where(reachable[:, None], terms >= 0, np.nan)
    flips = (np.abs(np.diff(config, axis=0)) == 1) & followed[:, None]  # NaN: never a flip
    return ReachReport(
        model=arm.name,
        joints=joints,
        unreachable=idx(~exists.any(axis=1)),
        limit_violations=idx(exists.any(axis=1) & ~reachable),
        wrist_singular=idx(reachable & (margins[:, 0] < wrist_tol)),
        elbow_singular=idx(reachable & (margins[:, 1] < elbow_tol)),
        shoulder_singular=idx(reachable & (margins[:, 2] < shoulder_tol_mm)),
        wrist_flips=idx(flips[:, 0]) + 1,
        config_flips=idx(flips.any(axis=1)) + 1,
        joint_jumps=idx(jumps) + 1,
        jump_deg=jump_deg,
        pass_jumps=idx(jumps & linked) + 1,
        margins=margins,
        limit_margin_rad=limit_margin(joints, limits),
    )
