"""The arm's links in the cell: capsules that enclose them (`Robot.link_capsules`) placed by
forward kinematics along the joint path, checked against the part, its fixtures and the
table block, at every target and along the joint moves into each pass.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.robot.base import Robot, inv_rigid
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import Cell
from scanplan.world.part import Part

# An arm over the table stands on it: its mounting face at most this above the top (a plate).
ON_TABLE_MM = 50.0
# Poses whose capsules lie within this of a checked pose's share its verdict (its capsules
# grown by how far theirs moved).
LINK_STRIDE_MM = 10.0
_MAX_SPAN = 64  # poses one check may stand for at most (of a pass that barely moves the arm)
# A joint move is checked at poses this far apart on its most turning joint.
JOINT_MOVE_STEP_RAD = np.radians(2.0)
# What the cell answered for a checked capsule set (its ends in part coordinates, radii,
# clearance and exactness, as bytes), and the quick check's answer for a whole path or
# joint move (`LinkClearance`): a fit checks the same passes round after round.
LinkMemo = dict[bytes, np.ndarray]


@dataclass(frozen=True)
class LinkReport:
    """Which poses put a link of the arm within `clearance_mm` of the cell.

    link, obstacle: (n,) the first colliding link's index into `links` and the obstacle's
    into `CellObstacles.NAMES`, -1 where none collides (or the pose has no joints).
    moves: {pose index: (link, obstacle)} of the joint moves into a pass (from the pose
    before it) that sweep a link into the cell.
    """

    links: tuple[str, ...]
    link: np.ndarray
    obstacle: np.ndarray
    moves: dict[int, tuple[int, int]]
    clearance_mm: float

    @property
    def colliding(self) -> np.ndarray:
        return self.link >= 0

    @property
    def clear(self) -> bool:
        return not (self.colliding.any() or self.moves)

    def describe(self, i: int) -> str:
        """What collides at pose i (its target, else the joint move into it)."""
        link, obstacle = (
            (int(self.link[i]), int(self.obstacle[i])) if self.link[i] >= 0 else self.moves[i]
        )
        where = "" if self.link[i] >= 0 else " on the joint move into it"
        return (
            f"puts the arm's {self.links[link]} within {self.clearance_mm:g} mm of the "
            f"{CellObstacles.NAMES[obstacle]}{where}"
        )

    def first(self) -> int:
        """The first pose whose target or entry move collides; -1 if none does."""
        found = [*np.flatnonzero(self.colliding)[:1], *sorted(self.moves)[:1]]
        return int(min(found)) if found else -1

    def summary(self) -> str:
        hits = self.obstacle[self.obstacle >= 0]
        by = ", ".join(
            f"{int((hits == k).sum())} {name}"
            for k, name in enumerate(CellObstacles.NAMES)
            if (hits == k).any()
        )
        return (
            f"arm links: {int(self.colliding.sum())} poses within {self.clearance_mm:g} mm of "
            f"the cell{f' ({by})' if by else ''}, {len(self.moves)} joint moves"
        )


def obstacles_for(
    part: Part,
    cell: Cell,
    sensor: SensorSpec | None = None,
    clearance_mm: float = ScanSpec.clearance_mm,
) -> CellObstacles:
    """What the links keep `clearance_mm` from (the plan's clearance, as the sensor body
    does): the part, the cell's fixtures and table block; with the sensor, what its body
    keeps that clearance from when a pose is changed (turned about the beam)."""
    return CellObstacles(part, cell, clearance_mm, sensor)


def _capsules_hit(
    robot: Robot,
    joints: np.ndarray,
    obstacles: CellObstacles,
    T_base_part: np.ndarray,
    clearance_mm: float,
    exact: bool = True,
    memo: LinkMemo | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(link, obstacle) per row of joints (m, 6): the first colliding link, -1 if none.

    Consecutive poses of a pass move the links by fractions of a millimetre, so not every
    pose goes to FCL: a checked pose stands for the poses after it whose capsule ends all
    lie within `LINK_STRIDE_MM` of its own (`_stride_groups`), each link's capsule grown by
    the furthest its ends moved among them (a point of a capsule moves no further than its
    ends do), and a hit is charged to all of them. T_base_part: (4, 4), or (m, 4, 4) one
    per row (the part moved by external axes)."""
    ends, radii, _ = robot.link_capsules(joints)
    T_part_base = inv_rigid(np.asarray(T_base_part, dtype=np.float64))
    if T_part_base.ndim == 2:
        ends = ends @ T_part_base[:3, :3].T + T_part_base[:3, 3]
    else:
        R, t = T_part_base[:, :3, :3], T_part_base[:, :3, 3]
        ends = np.einsum("mij,mkej->mkei", R, ends) + t[:, None, None, :]
    checked, covers, grown = _stride_groups(ends, radii)
    hit = _cell_hits(obstacles, ends[checked], grown, clearance_mm, exact, memo)[covers]
    colliding = hit >= 0
    link = np.where(colliding.any(axis=1), colliding.argmax(axis=1), -1)
    obstacle = np.where(link >= 0, hit[np.arange(len(hit)), np.maximum(link, 0)], -1)
    return link, obstacle


def _stride_groups(
    ends: np.ndarray, radii: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The poses checked for capsules `ends` (m, k, 2, 3) of `radii` (k,): (c,) the first
    pose of each group, (m,) the group of each pose, (c, k) each group's radii grown by the
    furthest its link's ends move from the first pose's. A group ends before the pose at
    which the capsule ends could have moved more than `LINK_STRIDE_MM` from its first:
    the most any end moves from pose to pose, summed, bounds how far they have (found for
    all poses at once; the walk from group to group is a hop a group), or at `_MAX_SPAN`
    poses."""
    m = len(ends)
    if m == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, len(radii)))
    step = np.sqrt((np.diff(ends, axis=0) ** 2).sum(axis=-1)).max(axis=(1, 2))
    travelled = np.r_[0.0, np.cumsum(step)]
    # The first pose beyond the stride from each pose, at most `_MAX_SPAN` on.
    beyond = np.searchsorted(travelled, travelled + LINK_STRIDE_MM, side="right")
    beyond = np.minimum(beyond, np.arange(m) + _MAX_SPAN).tolist()
    first, i = [], 0
    while i < m:
        first.append(i)
        i = beyond[i]
    starts = np.array(first)
    covers = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, m]))
    moved = np.sqrt(((ends - ends[starts][covers]) ** 2).sum(axis=-1)).max(axis=2)  # (m, k)
    return starts, covers, radii + np.maximum.reduceat(moved, starts, axis=0)


def _cell_hits(
    obstacles: CellObstacles,
    ends: np.ndarray,
    radii: np.ndarray,
    clearance_mm: float,
    exact: bool,
    memo: LinkMemo | None,
) -> np.ndarray:
    """`obstacles.capsules_hit` of capsules (n, k, 2, 3) of radii (n, k), asking the cell
    only for those `memo` does not know (each capsule set's answer is its own)."""
    if memo is None:
        return obstacles.capsules_hit(ends, radii, clearance_mm, exact)
    tag = np.array([clearance_mm, float(exact)]).tobytes()
    rows = np.concatenate([ends.reshape(len(ends), -1), radii], axis=1)
    keys = [tag + row.tobytes() for row in rows]
    new = [i for i, key in enumerate(keys) if key not in memo]
    if new:
        found = obstacles.capsules_hit(ends[new], radii[new], clearance_mm, exact)
        memo.update(zip([keys[i] for i in new], found, strict=True))
    return np.stack([memo[key] for key in keys]) if keys else np.zeros((0, radii.shape[1]), int)


def joint_path(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(k, 6) the joints strictly between q0 and q1 on the joint move from one to the other,
    at most `JOINT_MOVE_STEP_RAD` apart on the joint that turns most (none for a move
    shorter than two steps): the controller turns each joint by the difference of its
    (unwrapped) angles."""
    steps = int(np.ceil(np.abs(q1 - q0).max() / JOINT_MOVE_STEP_RAD))
    if steps < 2:
        return np.zeros((0, 6))
    return q0 + np.linspace(0.0, 1.0, steps + 1)[1:-1, None] * (q1 - q0)


def each_joint_move(
    joints: np.ndarray, entered: np.ndarray
) -> Iterator[tuple[int, int, np.ndarray]]:
    """(the pose before, the pose, `joint_path` between) of each joint move a program makes
    into the poses `entered` (n,) marks, from the last pose before with joints (`joints`
    (n, 6), NaN rows: none); moves too short to have steps between are left out."""
    known = np.flatnonzero(~np.isnan(joints).any(axis=1))
    for i in np.flatnonzero(entered):
        before = known[known < i]
        if not len(before) or i not in known:
            continue
        path = joint_path(joints[before[-1]], joints[i])
        if len(path):
            yield int(before[-1]), int(i), path


def check_links(
    robot: Robot,
    joints: np.ndarray,
    obstacles: CellObstacles,
    T_base_part: np.ndarray,
    pass_start: np.ndarray | None = None,
    clearance_mm: float | None = None,
    exact: bool = True,
    memo: LinkMemo | None = None,
) -> LinkReport:
    """The arm's links along `joints` (n, 6) rad (NaN rows: no joints, not checked) with the
    part at `T_base_part`: at every pose, and, where `pass_start` (n,) is True, along the
    joint move from the previous pose's joints into that pose's (the move a program makes
    into each pass), at steps of `JOINT_MOVE_STEP_RAD`. exact=False: without FCL, a few mm
    too cautious (`CellObstacles.capsules_hit`). T_base_part: (4, 4), or (n, 4, 4) one per
    pose (external axes; a joint move between two is checked with the part at both).
    memo: the cell's answers so far (`LinkMemo`), for a caller that checks much the same
    path again; the same report as without it."""
    clearance_mm = obstacles.clearance_mm if clearance_mm is None else clearance_mm
    joints = np.asarray(joints, dtype=np.float64)
    n = len(joints)
    link, obstacle = np.full(n, -1), np.full(n, -1)
    known = np.flatnonzero(~np.isnan(joints).any(axis=1))
    T_all = np.asarray(T_base_part, dtype=np.float64)
    per_pose = T_all.ndim == 3
    if len(known):
        link[known], obstacle[known] = _capsules_hit(
            robot,
            joints[known],
            obstacles,
            T_all[known] if per_pose else T_all,
            clearance_mm,
            exact,
            memo,
        )
    moves: dict[int, tuple[int, int]] = {}
    starts = np.zeros(n, bool) if pass_start is None else pass_start
    for before, i, path in each_joint_move(joints, starts):
        ends = (T_all[before], T_all[i]) if per_pose else (T_all,)
        for T in ends[: 1 if len(ends) == 1 or np.array_equal(*ends) else 2]:
            m_link, m_obstacle = _capsules_hit(robot, path, obstacles, T, clearance_mm, exact, memo)
            if (m_link >= 0).any():
                first = int(np.argmax(m_link >= 0))
                moves[int(i)] = (int(m_link[first]), int(m_obstacle[first]))
                break
    names = robot.link_capsules(np.zeros(6))[2]
    return LinkReport(names, link, obstacle, moves, float(clearance_mm))


class LinkClearance:
    """The arm's links in the cell as the reach check's choice of each pass's configuration
    asks (`pass_branches.CellView`): the quick check (`exact=False`) with the part at `T_base_part`
    (4, 4), or (n, 4, 4) one per pose of the path checked; `memo`: as `check_links`'s."""

    def __init__(
        self,
        robot: Robot,
        obstacles: CellObstacles,
        T_base_part: np.ndarray,
        memo: LinkMemo | None = None,
    ) -> None:
        self.robot, self.obstacles, self.memo = robot, obstacles, memo
        self.T = np.asarray(T_base_part, dtype=np.float64)

    def _at(self, i: int, m: int = 1) -> np.ndarray:
        return self.T[max(i, 0) : max(i, 0) + m] if self.T.ndim == 3 else self.T

    def clear_along(self, i: int, path: np.ndarray) -> np.ndarray:
        T = self._at(i, len(path))
        key = b""
        if self.memo is not None:
            # The fit's rounds ask again about passes they left as they were: the answer
            # for the whole path is remembered, not only its capsule sets'.
            key = b"along" + hashlib.sha256(path.tobytes() + T.tobytes()).digest()
            if key in self.memo:
                return self.memo[key]
        clear = np.stack(
            [
                ~check_links(
                    self.robot, path[:, k], self.obstacles, T, exact=False, memo=self.memo
                ).colliding
                for k in range(path.shape[1])
            ],
            axis=1,
        )
        if self.memo is not None:
            self.memo[key] = clear
        return clear

    def clear_move(self, i0: int, q0: np.ndarray, i1: int, q1: np.ndarray) -> bool:
        ends = (i0 if i0 >= 0 else i1, i1)
        T = self.T if self.T.ndim == 2 else np.stack([self._at(i)[0] for i in ends])
        joints = np.stack([q0, q1])
        key = b""
        if self.memo is not None:  # as `clear_along`'s: the same moves asked round after round
            key = b"move" + hashlib.sha256(joints.tobytes() + T.tobytes()).digest()
            if key in self.memo:
                return bool(self.memo[key])
        report = check_links(
            self.robot, joints, self.obstacles, T, np.array([False, True]), exact=False,
            memo=self.memo,
        )  # fmt: skip
        if self.memo is not None:
            self.memo[key] = np.array(not report.moves)
        return not report.moves


def hung(T_base_part: np.ndarray) -> np.ndarray:
    """(P,) whether each placement (P, 4, 4) hangs the arm upside down: its base's z axis
    points down in the part's frame (an arm hung from an overhead track)."""
    return np.asarray(T_base_part, dtype=np.float64).reshape(-1, 4, 4)[:, 2, 2] < 0.0


def swept_column(robot: Robot) -> tuple[float, float, float]:
    """The links that turn with joint 1 only (column and shoulder) swept about the vertical:
    their radius and lowest and highest points in the base frame (mm)."""
    ends, radii, _ = robot.link_capsules(np.zeros(6))
    sweep = float((np.hypot(ends[:2, :, 0], ends[:2, :, 1]) + radii[:2, None]).max())
    z_lo = float((ends[:2, :, 2] - radii[:2, None]).min())
    z_hi = float((ends[:2, :, 2] + radii[:2, None]).max())
    return sweep, z_lo, z_hi


def on_table_z(
    robot: Robot, block: tuple[np.ndarray, np.ndarray], clearance_mm: float
) -> float | None:
    """The part's height in the base frame (T_base_part's z, the part level) that stands an
    upright arm on the table block's top as `column_clear` lets it: its column 1 mm above
    the clearance (placements at a few heights apart seldom land in that slab); None for
    an arm whose column reaches below its base frame too far for that (its base frame is
    `ON_TABLE_MM` at most above the top)."""
    _, z_lo, _ = swept_column(robot)
    lift = max(clearance_mm - z_lo, 0.0) + 1.0
    return -(float(block[1][2]) + lift) if lift <= ON_TABLE_MM else None


def _off_footprint(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(…, 2) how far each point (…, 3) lies outside the box lo..hi in x and in y (0 over
    its footprint)."""
    return np.maximum(np.maximum(lo[:2] - points[..., :2], points[..., :2] - hi[:2]), 0.0)


def column_clear(
    robot: Robot,
    T_base_part: np.ndarray,
    block: tuple[np.ndarray, np.ndarray] | None,
    clearance_mm: float,
    part_bounds: np.ndarray | None = None,
) -> np.ndarray:
    """(P,) whether the arm can stand where placements T_base_part (P, 4, 4; turning the
    part about the vertical only, or also upside down for an arm hung from above) put it,
    beside the table block (lo, hi in part coordinates) or on the table: the links that
    turn with joint 1 only (the first two capsules, column and shoulder), swept about the
    vertical, keep `clearance_mm` from the block, and an upright arm over the block stands
    on its top (within `ON_TABLE_MM`), not on a riser nothing models; a hung arm over it
    hangs above its top. With `part_bounds` ((2, 3) lo, hi), its joint-1 axis stands off
    the part's footprint unless the column is wholly above or below the part: an arm does
    not stand under a curved panel's span (next to a part, its links are checked against
    it as everywhere). A cheap test the placement search runs on every candidate."""
    T = np.asarray(T_base_part, dtype=np.float64).reshape(-1, 4, 4)
    sweep, z_lo, z_hi = swept_column(robot)
    axis_in_part = inv_rigid(T)[:, :3, 3]  # the base origin, on the joint-1 axis
    base_z = axis_in_part[:, 2]
    down = hung(T)
    bottom = np.where(down, base_z - z_hi, base_z + z_lo)  # the column's lowest point
    top = np.where(down, base_z - z_lo, base_z + z_hi)
    ok = np.ones(len(T), bool)
    if part_bounds is not None:
        lo, hi = np.asarray(part_bounds[0]), np.asarray(part_bounds[1])
        under = ~_off_footprint(axis_in_part, lo, hi).any(axis=1)  # its axis over the box
        ok &= ~(under & (bottom < hi[2] + clearance_mm) & (top > lo[2] - clearance_mm))
    if block is None:
        return ok
    lo, hi = np.asarray(block[0]), np.asarray(block[1])
    gap_xy = _off_footprint(axis_in_part, lo, hi)
    gap_z = np.maximum(lo[2] - top, bottom - hi[2])
    beside = np.linalg.norm(gap_xy, axis=1) > sweep + clearance_mm
    on_top = (gap_z > clearance_mm) & (base_z - hi[2] <= ON_TABLE_MM)
    hangs_above = down & (bottom - hi[2] > clearance_mm)
    return ok & (beside | np.where(down, hangs_above, on_top))


def stands_in_cell(robot: Robot, T_base_part: np.ndarray, obstacles: CellObstacles) -> np.ndarray:
    """`column_clear` among a cell's `obstacles`: off its table block and the part."""
    return column_clear(
        robot, T_base_part, obstacles.table_block, obstacles.clearance_mm, obstacles.part_bounds
    )


def where_it_stands(
    T_base_part: np.ndarray, block: tuple[np.ndarray, np.ndarray] | None
) -> dict | None:
    """Where an upright arm's base stands for a user setting up the cell: on the table
    block's top (`column_clear` lets it) or beside it, with its base origin in part
    coordinates (mm), its height over the top (and whether that is the top's, within
    `ON_TABLE_MM`) and, beside, its axis's distance from the block's edge. None without a
    table, or for an arm hung from above."""
    T = np.asarray(T_base_part, dtype=np.float64)
    if block is None or hung(T)[0]:
        return None
    lo, hi = np.asarray(block[0]), np.asarray(block[1])
    base = inv_rigid(T)[:3, 3]
    gap_xy = _off_footprint(base, lo, hi)
    above = float(base[2] - hi[2])
    said = {
        "on_table": bool(not gap_xy.any()),
        # Beside its footprint but at its top's height: on a stand level with the table.
        "level_with_top": bool(0.0 <= above <= ON_TABLE_MM),
        "base_in_part_mm": (np.round(base, 1) + 0.0).tolist(),  # no "-0"
        "above_top_mm": round(above, 1),
    }
    if gap_xy.any():
        said["from_edge_mm"] = round(float(np.linalg.norm(gap_xy)), 1)
    return said


__all__ = [
    "LinkClearance",
    "LinkMemo",
    "LinkReport",
    "check_links",
    "column_clear",
    "stands_in_cell",
    "hung",
    "obstacles_for",
    "on_table_z",
    "swept_column",
    "where_it_stands",
]
