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
from scanplan.robot.pass_branches import CellView, by_flown, flown_count
from scanplan.robot.presets import get_robot

TWO_PI = 2 * np.pi

# A joint turning more than this between consecutive poses of a pass is a jump: no longer
# the branch the controller follows there (`check_reach`).
JUMP_DEG = 30.0


def fit_limits(q: np.ndarray, limits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q shifted by whole turns into the limits where it can be, (…,) all joints inside).
    Ranges wider than ±180° (KUKA A6 ±350°, UR ±360°) make several turns legal: the one
    closest to the given q is kept."""
    lo, hi = limits[:, 0], limits[:, 1]
    # A turn down where above the range, up where below (never both: lo < hi), by
    # arithmetic on the tests: the same values as choosing with `np.where`, at a third of
    # its cost.
    for _ in range(2):
        q = q - TWO_PI * (q > hi) + TWO_PI * (q < lo)
    return q, reduce_last_axis((q >= lo - 1e-12) & (q <= hi + 1e-12), np.logical_and)


def limit_margin(q: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """(…,) rad to the nearest joint limit (negative beyond it)."""
    return reduce_last_axis(np.minimum(q - limits[:, 0], limits[:, 1] - q), np.minimum)


def reduce_last_axis(per_joint: np.ndarray, combine: np.ufunc) -> np.ndarray:
    """`combine` reduced over the last axis (joints, singularity terms) column by column:
    numpy's reduction over a short last axis costs twice to ten times as much, and the
    placement search reduces millions of solutions."""
    out = combine(per_joint[..., 0], per_joint[..., 1])
    for j in range(2, per_joint.shape[-1]):
        combine(out, per_joint[..., j], out=out)
    return np.asarray(out)


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
        if len(solutions) == 1:  # a move's pose: every branch flies it, the nearest wins
            cand = first[ok]
            return cand[np.argmin(((cand - prev) ** 2).sum(axis=1))]
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


def _candidates(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(m, 8, 6) each pose's solutions turned the way nearest `prev` (m, 6) and shifted into
    the limits where they can be; (m, 8) their squared distance to `prev`, inf where there
    is no solution within the limits."""
    cand, inside = fit_limits(prev[:, None] + wrap(solutions - prev[:, None]), limits)
    inside &= ~np.isnan(cand).any(axis=-1)
    dist = np.where(inside, ((cand - prev[:, None]) ** 2).sum(axis=-1), np.inf)
    return cand, dist


def nearest_solution(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray
) -> tuple[int, np.ndarray] | None:
    """(branch, joints) of the one pose's (1, 8, 6) in-limit solution nearest `prev` (1, 6),
    as a controller moving linearly takes it; None if it has none within the limits."""
    cand, dist = _candidates(solutions, limits, prev)
    branch = int(np.argmin(dist[0]))
    return None if not np.isfinite(dist[0, branch]) else (branch, cand[0, branch])


def _next_within(
    solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray, lo: int, hi: int
) -> int:
    """The first pose from `lo` on, before `hi`, with an in-limit solution from `prev` (`hi`
    if none): the poses `check_reach` would step one by one, finding none, while its joints
    stay at `prev`. Looked for in growing windows, so a short gap costs a short look."""
    size = 8
    while lo < hi:
        top = min(hi, lo + size)
        _, dist = _candidates(solutions[lo:top], limits, np.broadcast_to(prev, (top - lo, 6)))
        found = np.isfinite(dist).any(axis=1)
        if found.any():
            return lo + int(np.argmax(found))
        lo, size = top, size * 8
    return hi


def _follow(solutions: np.ndarray, limits: np.ndarray, prev: np.ndarray, branch: int) -> np.ndarray:
    """(t, 6) the joints of the first t poses of `solutions` (m, 8, 6) while taking, pose by
    pose, the in-limit solution nearest the previous joints (`nearest_solution`) stays on
    `branch` from `prev`: each pose checked against the branch's path unwrapped from `prev` at once,
    so a pass costs a few array operations instead of a Python step a pose. t stops at the
    first pose where the nearest is another branch, or none (the caller steps it alone)."""
    if not len(solutions):
        return np.zeros((0, 6))
    along = solutions[:, branch]
    path = prev + np.cumsum(wrap(np.diff(np.r_[prev[None], along], axis=0)), axis=0)
    before = np.r_[prev[None], path[:-1]]
    cand, dist = _candidates(solutions, limits, before)
    held = (np.argmin(dist, axis=1) == branch) & np.isfinite(dist[:, branch])
    # Shifted by a turn into the limits, or off the unwrapped path: stepped alone.
    held &= (np.abs(cand[:, branch] - path) < 1e-9).all(axis=1)
    t = len(held) if held.all() else int(np.argmin(held))
    return cand[:t, branch]


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

    Each pass (and each pose outside a pass) is entered on the branch that flies the most
    of it (`_pass_start`; the first reachable pose on the solution closest to `q_start` if
    given), with the arm's links clear of the `cell` along it and on the joint move into
    it if a cell is given; or at the solution nearest the joints `entries` records for its
    first pose (the configurations a fit chose, as its plan records them). entry: (n,)
    where each pass is entered (`trajectory.pass_entries`: the top of the move leading into
    it, the move's poses after it flown on the pass's configuration); None: at its first
    pose. restarts: (n,) True where another path starts (on a pass of its own), followed
    as if checked alone (no joints before it; `q_start` is the first path's): several
    paths in one call. Each next pose of a pass takes the in-limit solution closest to the
    previous one, as a controller executing linear moves would. A configuration flip is a
    sign change of a singularity term (wrist, elbow, shoulder) between consecutive poses of
    one pass (`swath`, `scanning`; without them the whole path is one pass): the path went
    through that singularity. A jump is any joint turning more than `jump_deg` between consecutive
    poses.
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
    followed = linked
    if entry is not None:
        followed = _runs_linked(np.asarray(entry, dtype=bool), swath, scanning, linked)
    entered = np.r_[True, ~followed]
    pinned = q_start is not None
    last = -1  # the pose `prev` is the joints of (-1: none, or `q_start`)
    path_of = np.zeros(n, int) if restarts is None else np.cumsum(restarts)
    prev_path = path_of[0] if n else 0  # the path `prev` belongs to
    end = _run_ends(followed)
    # Sequential by nature (each pose's branch depends on the previous choice), but within a
    # pass the choice follows one branch: checked for a whole run at once (`_follow`).
    i = 0
    while i < n:
        if prev is not None and path_of[i] != prev_path:  # another path: none before it
            prev, last, pinned = None, -1, False
        if not exists[i].any():
            i += 1
            continue
        prev_path = path_of[i]
        if prev is None or (entered[i] and not pinned):
            if entries is not None and i in entries:  # the configuration recorded
                found = nearest_solution(solutions[i : i + 1], limits, np.asarray(entries[i])[None])
                start = None if found is None else found[1]
            else:
                start = _pass_start(
                    arm, solutions[i : end[i]], limits, prev, tol, jump_deg, cell, (i, last)
                )
            if start is None:
                i += 1
                continue
            prev, last = start, i
            joints[i] = prev
            i += 1
            continue
        # In a pass, or the first pose when the caller gave `q_start`: the in-limit
        # solution nearest the previous joints.
        pinned = False
        nearest = nearest_solution(solutions[i : i + 1], limits, prev[None])
        if nearest is None:
            i = _next_within(solutions, limits, prev, i + 1, end[i])
            continue
        branch, prev = nearest
        joints[i], last = prev, i
        ran = _follow(solutions[i + 1 : end[i]], limits, prev, branch)
        if len(ran):
            joints[i + 1 : i + 1 + len(ran)] = ran
            prev, last = ran[-1], i + len(ran)
        i += 1 + len(ran)
    return _report(arm, joints, exists, linked, tol, jump_deg, followed)


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
