"""A plan flown with external axes (`axes`): the turntable indexed per view, the track
following the sensor at an offset held per view.

For each view (a block of passes in `meta['views']`, with the moves into it) the axis setting
is chosen at which the placed arm flies most of that view's scanning poses (reach, joint
limits, links; `flown_poses.flyable_poses`, as `fit.fit_to_robot` keeps poses). The turntable
holds its angle over the view and turns on the joint move into it (at the move's pose
farthest from the part, so the arm swings where it is clear); the track holds the arm at a
fixed offset along it from the sensor (s = d·flange - offset, clipped to its travel), so a
pass along the track is flown with the arm riding with it, and a pass across it with the arm
standing. The arm's placement is searched with the axes: its distance from the turntable's
axis and its height (the turntable turns the rest), or the placement and the track's
direction (along the part's long side).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from scanplan.core.context import PlanContext
from scanplan.core.plan import ViewRecord, view_records
from scanplan.core.trajectory import Trajectory
from scanplan.robot.axes import ExternalAxes, kept, part_poses, with_disk
from scanplan.robot.base import Robot
from scanplan.robot.fit import PlacedArm, renumbered_passes
from scanplan.robot.flown_poses import HALF_TURN, flyable_poses, kept_by_pass, turned_passes
from scanplan.robot.flyable import stands_clear
from scanplan.robot.links import hung, obstacles_for
from scanplan.robot.place import place, reach_mm, sample_poses
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import check_reach
from scanplan.world.capsule_collision import CellObstacles
from scanplan.world.cell import planned_cell
from scanplan.world.part import Part

TURN_STEP_DEG = 15.0  # the turntable's candidate angles, this far apart
TRACK_OFFSETS = 9  # the track's candidate offsets, across the arm's reach
# With a turntable and a track, the placement search judges each stand on a coarser grid.
COARSE_TURN_STEP_DEG = 45.0
COARSE_TRACK_OFFSETS = 5
SAMPLE_POSES = 96  # a view's poses a candidate setting is judged on
# Among settings within this share of the best, the one nearest the last view's is held
# (the axis moves less).
NEAR_BEST = 0.01
# The arm's column stands at least this far outside the turntable's disk.
BESIDE_DISK_MM = 150.0
# With a track, the placement is searched across it and in height about the arm's own.
TRACK_ACROSS_MM = np.arange(-400.0, 401.0, 100.0)
TRACK_HEIGHTS_MM = np.arange(-300.0, 301.0, 150.0)
# Hung from an overhead track: the base this far above the part's top, and beside the part's
# centre line across the track.
OVERHEAD_HEIGHTS_MM = np.array([300.0, 450.0, 600.0, 800.0, 1000.0])
OVERHEAD_ACROSS_MM = np.array([-300.0, -150.0, 0.0, 150.0, 300.0])
# An overhead track (a gantry over the table) is chosen over a floor one only when it keeps
# this much more of the sampled scanning poses: a floor track is the simpler cell.
OVERHEAD_GAIN = 0.05
# The placements judged again with the arm's links: those within this share of the best
# on reach alone (many tie there; the links tell them apart).
LINK_CHECKED_WITHIN = 0.1
# Each view of those placements judged again at the settings reach alone ranked first.
LINK_SETTINGS = 6


def resolved(axes: ExternalAxes, part: Part, T_base_part: np.ndarray, traj: Trajectory):
    """`axes` with what the tool chooses filled in: the turntable's axis through the centre
    of the part's footprint at its lowest point (the part centred on the disk), the track
    along the longer horizontal side of the scanning path in the base frame, mounted as the
    placement has it (overhead when the arm's base faces down). ValueError when a track's
    mount given contradicts the placement."""
    lo, hi = part.bounds
    point = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    T = np.asarray(T_base_part)
    direction = long_side(traj, T)
    mount = "overhead" if hangs(T) else "floor"
    if axes.track is not None and axes.track.mount not in (None, mount):
        raise ValueError(
            f"the track is mounted {axes.track.mount}, but the part's pose puts the arm "
            f"{'upside down' if mount == 'overhead' else 'upright'}"
        )
    if direction is None:
        direction = np.array([1.0, 0.0, 0.0])
    return axes.with_choices(point, direction, mount)


def hangs(T_base_part: np.ndarray) -> bool:
    """Whether the arm's base faces down in the part's frame (hung from an overhead track)."""
    return bool(hung(T_base_part)[0])


def long_side(traj: Trajectory, T_frame_part: np.ndarray) -> np.ndarray | None:
    """The unit horizontal direction (in the frame `T_frame_part` maps the part into) along
    which the scanning path is longest, its largest component positive; None for < 2 poses."""
    xy = (np.asarray(T_frame_part) @ traj.poses[traj.scanning])[:, :2, 3]
    if len(xy) < 2:
        return None
    _, _, vt = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)
    direction = np.array([vt[0, 0], vt[0, 1], 0.0])
    return direction * np.sign(direction[np.argmax(np.abs(direction))])


def candidates(axes: ExternalAxes, robot: Robot, coarse: bool = False) -> np.ndarray:
    """(c, k) settings to try: turntable angles `TURN_STEP_DEG` apart over its range; track
    offsets (the flange's position along it relative to the base) across the arm's reach.
    coarse: with both axes, the grid the placement search judges each stand on (their
    product is too many settings to score at every stand)."""
    both = coarse and axes.turntable is not None and axes.track is not None
    step = COARSE_TURN_STEP_DEG if both else TURN_STEP_DEG
    offsets = COARSE_TRACK_OFFSETS if both else TRACK_OFFSETS
    columns = []
    if axes.turntable is not None:
        lo, hi = axes.turntable.limits_deg
        span = min(hi - lo, 360.0 - step)
        columns.append(lo + np.arange(0.0, span + 1e-9, step))
    if axes.track is not None:
        reach = reach_mm(robot)[0]
        columns.append(np.linspace(-0.6 * reach, 0.6 * reach, offsets))
    grid = np.meshgrid(*columns, indexing="ij")
    return np.stack([g.reshape(-1) for g in grid], axis=1)


def values_at(
    axes: ExternalAxes,
    setting: np.ndarray,
    T_base_part: np.ndarray,
    poses: np.ndarray,
    inv_tcp: np.ndarray,
) -> np.ndarray:
    """(n, k) the axes' values at `poses` (part frame) for a `setting` (k,): the turntable's
    angle as it is; the track at s = d·flange - offset (the flange's along-track position
    at the turntable's angle), clipped to its travel."""
    values = np.tile(np.asarray(setting, dtype=np.float64), (len(poses), 1))
    if axes.track is not None:
        assert axes.track.direction is not None
        d = np.asarray(axes.track.direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        at = values.copy()
        at[:, -1] = 0.0
        flange = (part_poses(T_base_part, at, axes) @ poses @ inv_tcp)[:, :3, 3]
        lo, hi = axes.limits[-1]
        values[:, -1] = np.clip(flange @ d - setting[-1], lo, hi)
    return values


def _blocks(traj: Trajectory) -> list[np.ndarray]:
    """(n,) masks: each view's poses (its passes and the moves into them), in order."""
    views = view_records(traj) or (ViewRecord(0, (0.0, 0.0, 1.0), 0, 1 << 30, 0),)
    out = [v.holds(traj.swath) for v in views]
    return [m for m in out if m.any()]


def _score(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    axes: ExternalAxes,
    settings: np.ndarray,
    index: np.ndarray,
) -> np.ndarray:
    """(c,) the scanning poses among `index` kept at each setting (each pass as planned
    or turned half a turn, as the fit keeps them)."""
    out = np.zeros(len(settings))
    sub = traj.subset(np.isin(np.arange(len(traj)), index))
    scanning = sub.scanning
    for c, setting in enumerate(settings):
        T = part_poses(T_base_part, values_at(axes, setting, T_base_part, sub.poses, inv_tcp), axes)
        if obstacles is None:
            good = [
                ~np.isnan(
                    check_reach(T @ p @ inv_tcp, arm, swath=sub.swath, scanning=scanning).joints
                ).any(axis=1)
                for p in (sub.poses, sub.poses @ HALF_TURN)
            ]
        else:
            good = list(flyable_poses(sub, arm, T, inv_tcp, obstacles, exact=False))
        out[c] = kept_by_pass(sub.swath, good[0], good[1])[scanning].sum()
    return out


def _pick(scores: np.ndarray, settings: np.ndarray, last: np.ndarray | None) -> int:
    """The best setting; among those within NEAR_BEST of it, the nearest to `last` (to
    every axis at 0 for the first view)."""
    near = np.flatnonzero(scores >= scores.max() * (1.0 - NEAR_BEST) - 1e-9)
    last = np.zeros(settings.shape[1]) if last is None else last
    return int(near[np.argmin(np.abs(settings[near] - last).sum(axis=1))])


def choose_values(
    traj: Trajectory,
    robot: str | Path | Robot,
    tcp: np.ndarray,
    T_base_part: np.ndarray,
    axes: ExternalAxes,
    obstacles: CellObstacles | None = None,
    part_centre: np.ndarray | None = None,
) -> tuple[Trajectory, list[np.ndarray]]:
    """`traj` with its external axis values (`Trajectory.external`) chosen view by view,
    and each view's setting. The turntable turns on the move into a view at the move's pose
    farthest from `part_centre` (part frame; the path's centre if None)."""
    arm = get_robot(robot)
    inv_tcp = np.linalg.inv(tcp)
    settings = candidates(axes, arm)
    centre = traj.positions_mm.mean(axis=0) if part_centre is None else part_centre
    values = np.zeros((len(traj), len(axes.names)))
    chosen: list[np.ndarray] = []
    last = None
    for block in _blocks(traj):
        index = np.flatnonzero(block)
        scan = index[traj.scanning[index]]
        if not len(scan):
            scan = index
        sample = scan[sample_poses(traj.subset(np.isin(np.arange(len(traj)), scan)), SAMPLE_POSES)]
        scores = _score(traj, arm, T_base_part, inv_tcp, obstacles, axes, settings, sample)
        best = settings[_pick(scores, settings, last)]
        chosen.append(best)
        values[index] = values_at(axes, best, T_base_part, traj.poses[index], inv_tcp)
        if last is not None and axes.turntable is not None:
            # The turntable turns on the move in, at its pose farthest from the part.
            lead = (
                index[: int(np.argmax(traj.scanning[index]))]
                if traj.scanning[index].any()
                else index
            )
            if len(lead):
                far = lead[int(np.argmax(np.linalg.norm(traj.positions_mm[lead] - centre, axis=1)))]
                values[index[0] : far, 0] = last[0]
        last = best
    return replace(traj, external=values), chosen


class PlacedArmOnAxes(PlacedArm):
    """A `PlacedArm` with external axes: a candidate view is flown at the setting that keeps
    most of it (`choose_values` on the view alone)."""

    def __init__(
        self,
        robot: str | Path,
        tcp: np.ndarray,
        T_base_part: np.ndarray,
        context: PlanContext,
        axes: ExternalAxes,
    ) -> None:
        super().__init__(robot, tcp, T_base_part, context)
        self.axes = axes

    def obstacles(self, part: Part) -> CellObstacles:
        """The cell's obstacles with the turntable's disk among them."""
        if self._obstacles is None or self._obstacles[0] != id(part):
            spec = self.context.spec
            cell = with_disk(planned_cell(self.context, part), self.axes)
            self._obstacles = (id(part), obstacles_for(part, cell, spec.sensor, spec.clearance_mm))
        return self._obstacles[1]

    def flown(self, part: Part, traj: Trajectory) -> Trajectory:
        arm = get_robot(self.robot)
        obstacles = self.obstacles(part)
        single = replace(traj, meta={k: v for k, v in traj.meta.items() if k != "views"})
        with_axes, _ = choose_values(single, arm, self.tcp, self.T_base_part, self.axes, obstacles)
        T = part_poses(self.T_base_part, with_axes.external, self.axes)
        inv_tcp = np.linalg.inv(self.tcp)
        planned, turned = flyable_poses(with_axes, arm, T, inv_tcp, obstacles, exact=False)
        scanning = traj.scanning
        turn = np.isin(
            traj.swath, turned_passes(traj.swath[scanning], planned[scanning], turned[scanning])
        )
        keep = np.where(turn, turned, planned) | ~scanning
        poses = np.where(turn[:, None, None], traj.poses @ HALF_TURN, traj.poses)
        swath = renumbered_passes(traj, keep, traj.swath, np.zeros(len(traj), bool))
        return replace(traj, poses=poses).subset(keep, swath)


def place_on_axes(
    traj: Trajectory,
    robot: str | Path | Robot,
    tcp: np.ndarray,
    axes: ExternalAxes,
    part: Part,
    T_base_part: np.ndarray,
    obstacles: CellObstacles | None = None,
) -> tuple[np.ndarray, ExternalAxes]:
    """The placement (and the axes' choices) from which the arm with its axes flies most of
    `traj`'s scanning: from `T_base_part` (the arm's own placement for the plan), for a
    turntable also the part's axis at distances and heights around the arm's reach (the
    arm's column outside the disk), for a track the part moved across the track and up or
    down, and the arm hung from an overhead track over the part (`overhead_tries`, unless
    the track is given as a floor one); each judged by the scanning poses the best per-view
    settings keep (reach and limits, on a sample), the arm's column clear of the table. An
    overhead track is taken only when it keeps `OVERHEAD_GAIN` more than the floor's best."""
    arm = get_robot(robot)
    inv_tcp = np.linalg.inv(tcp)
    floor: list[np.ndarray] = []
    mount = None if axes.track is None else axes.track.mount
    if mount != "overhead":
        floor.append(np.asarray(T_base_part, dtype=np.float64))
    if axes.turntable is not None and mount != "overhead":
        reach, z_mid = reach_mm(arm)
        point = resolved(axes, part, T_base_part, traj).turntable.axis_point_mm  # type: ignore[union-attr]
        beside = axes.turntable.radius_mm + BESIDE_DISK_MM
        for r in np.linspace(max(0.3 * reach, beside), max(0.8 * reach, beside + 100.0), 6):
            for z in z_mid + np.linspace(-0.5, 0.2, 5) * reach:
                T = np.eye(4)
                T[:3, 3] = np.array([r, 0.0, z]) - np.asarray(point)
                floor.append(T)
    if axes.track is not None and mount != "overhead":  # nearer or farther, higher, lower
        d = np.asarray(resolved(axes, part, T_base_part, traj).track.direction)  # type: ignore[union-attr]
        across = np.array([-d[1], d[0], 0.0])
        for u in TRACK_ACROSS_MM:
            for z in TRACK_HEIGHTS_MM:
                T = np.array(T_base_part, dtype=np.float64)
                T[:3, 3] += u * across + [0.0, 0.0, z]
                floor.append(T)
    overhead = [] if axes.track is None or mount == "floor" else overhead_tries(traj, part)
    if obstacles is not None:  # the arm's column beside the table, not in it, all along its rail

        def clear(tries: list[np.ndarray]) -> list[np.ndarray]:
            return [
                T for T in tries if stands_clear(arm, T, resolved(axes, part, T, traj), obstacles)
            ]

        # None clear: the arm's own placement, which export will refuse with its reason.
        floor, overhead = clear(floor), clear(overhead)
        if not floor and not overhead:
            floor = [np.asarray(T_base_part, dtype=np.float64)]
    best, best_score = _best_placement(traj, arm, inv_tcp, axes, part, floor, obstacles)
    if overhead:
        high, high_score = _best_placement(traj, arm, inv_tcp, axes, part, overhead, obstacles)
        if best is None or high_score > best_score + OVERHEAD_GAIN:
            best = high
    if best is None:  # every stand in the turntable: the arm's own, which export will refuse
        best = np.asarray(T_base_part, dtype=np.float64)
    return best, resolved(axes, part, best, traj)


def overhead_tries(traj: Trajectory, part: Part) -> list[np.ndarray]:
    """Placements (`T_base_part`) of the arm hung upside down from an overhead track over
    the part: its base `OVERHEAD_HEIGHTS_MM` above the part's top, over the part's centre
    line along its long side and `OVERHEAD_ACROSS_MM` beside it, its x axis along or
    across that side."""
    lo, hi = part.bounds
    d = long_side(traj, np.eye(4))
    d = np.array([1.0, 0.0, 0.0]) if d is None else d
    across = np.array([-d[1], d[0], 0.0])
    down = np.array([0.0, 0.0, -1.0])
    out = []
    for x in (d, across):
        R = np.column_stack([x, np.cross(down, x), down])
        for h in OVERHEAD_HEIGHTS_MM:
            for u in OVERHEAD_ACROSS_MM:
                T_part_base = np.eye(4)
                T_part_base[:3, :3] = R
                T_part_base[:3, 3] = (lo + hi) / 2 + u * across
                T_part_base[2, 3] = hi[2] + h
                out.append(np.linalg.inv(T_part_base))
    return out


def _best_placement(
    traj: Trajectory,
    arm: Robot,
    inv_tcp: np.ndarray,
    axes: ExternalAxes,
    part: Part,
    tries: list[np.ndarray],
    obstacles: CellObstacles | None,
) -> tuple[np.ndarray | None, float]:
    """(the placement among `tries` whose best per-view settings keep most of a sample of
    `traj`'s scanning poses, that share); (None, -1) when none is tried. Each is judged
    on reach and limits, then those near the best also with the arm's links (the quick
    test) against `obstacles`: an arm standing amid the part, or hung low over it,
    reaches it all."""
    best, best_score = None, -1.0
    sample = sample_poses(traj, 4 * SAMPLE_POSES)
    sub = traj.subset(np.isin(np.arange(len(traj)), sample))
    scored: list[tuple[float, list[np.ndarray], np.ndarray]] = []
    for T in tries:
        choice = resolved(axes, part, T, traj)
        t = choice.turntable
        if t is not None and t.axis_point_mm is not None and not hangs(T):
            base = np.linalg.inv(T)[:3, 3]
            if np.hypot(*(base - t.axis_point_mm)[:2]) < t.radius_mm + BESIDE_DISK_MM:
                continue  # the arm's column in the turntable
        scored.append((*_kept_share(sub, arm, T, inv_tcp, None, choice), T))
    scored.sort(key=lambda st: -st[0])
    if obstacles is not None and scored:  # the links on those near the best
        top = scored[0][0]
        scored = [
            (
                *_kept_share(
                    sub, arm, T, inv_tcp, obstacles, resolved(axes, part, T, traj), settings
                ),
                T,
            )
            for score, settings, T in scored
            if score >= top - LINK_CHECKED_WITHIN
        ]
    for score, _, T in scored:
        if score > best_score + 1e-9:
            best, best_score = T, score
    return best, best_score


def _kept_share(
    sub: Trajectory,
    arm: Robot,
    T: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    axes: ExternalAxes,
    tried: list[np.ndarray] | None = None,
) -> tuple[float, list[np.ndarray]]:
    """The share of `sub`'s scanning poses the best per-view settings of `axes` keep with
    the arm at `T` (`_score`), and each view's `LINK_SETTINGS` best settings. tried: the
    settings to judge each view on (all by default: those the reach alone ranked first,
    when the links judge them again)."""
    every = candidates(axes, arm, coarse=True)
    score, best = 0.0, []
    for k, block in enumerate(_blocks(sub)):
        index = np.flatnonzero(block & sub.scanning)
        settings = every if tried is None else tried[k]
        if not len(index) or not len(settings):
            best.append(settings[:0])
            continue
        kept = _score(sub, arm, T, inv_tcp, obstacles, axes, settings, index)
        score += kept.max()
        best.append(settings[_first(kept, LINK_SETTINGS)])
    return score / max(int(sub.scanning.sum()), 1), best


def _first(scores: np.ndarray, n: int) -> np.ndarray:
    """The indices of the n best `scores`; where more tie for the best, n spread evenly
    among them (settings far apart differ most in where the links go)."""
    order = np.argsort(-scores, kind="stable")
    tied = order[scores[order] >= scores.max() - 1e-9]
    if len(tied) > n:
        return tied[np.linspace(0, len(tied) - 1, n).round().astype(int)]
    return order[:n]


def arm_on_axes(
    traj: Trajectory,
    robot: str | Path,
    tcp: np.ndarray,
    T_base_part: np.ndarray | None,
    axes: ExternalAxes,
    part: Part,
    obstacles: CellObstacles | None,
) -> tuple[np.ndarray, ExternalAxes]:
    """(T_base_part, the axes with the tool's choices) for `traj` (a plan without the arm):
    the placement given, else the arm's own (`place.place`) searched with the axes
    (`place_on_axes`); the turntable's point and the track's direction as given, else the
    tool's (`resolved`)."""
    if T_base_part is not None:
        return np.asarray(T_base_part, dtype=np.float64), resolved(axes, part, T_base_part, traj)
    T0 = place(traj, robot, tcp, obstacles=obstacles).T_base_part
    return place_on_axes(traj, robot, tcp, axes, part, T0, obstacles)


def fitted_axes_record(axes: ExternalAxes, traj: Trajectory) -> dict:
    """What the arm's record holds of the axes: their description, and how far each moves
    over the plan (sum of |Δ|, degrees or mm)."""
    travel = [] if traj.external is None else np.abs(np.diff(traj.external, axis=0)).sum(axis=0)
    return axes.record() | {"travel": [round(float(t), 3) for t in travel]}


__all__ = [
    "PlacedArmOnAxes",
    "arm_on_axes",
    "candidates",
    "choose_values",
    "hangs",
    "long_side",
    "overhead_tries",
    "fitted_axes_record",
    "kept",
    "place_on_axes",
    "resolved",
    "values_at",
]
