"""A plan flown with external axes (`axes`): the turntable indexed per view, the track
following the sensor at an offset held per view.

For each view (a block of passes in `meta['views']`, with the moves into it) the axis setting
is chosen at which the placed arm flies most of that view's scanning poses (reach, joint
limits, links; `flown_poses.flyable_poses`, as `fit.fit_to_robot` keeps poses). The turntable
holds its angle over the view and turns on the joint move into it (at the move's pose
farthest from the part, so the arm swings where it is clear); the track holds the arm at a
fixed offset along it from the sensor (s = d·flange - offset, clipped to its travel), so a
pass along the track is flown with the arm riding with it, and a pass across it with the arm
standing. Where the arm stands with them is `axes_place`'s.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from scanplan.core.context import PlanContext
from scanplan.core.plan import ViewRecord, view_records
from scanplan.core.trajectory import Trajectory
from scanplan.robot.axes import ExternalAxes, kept, part_poses, with_disk
from scanplan.robot.axes_kept import kept_each, reach_bound_each, values_at
from scanplan.robot.base import Robot
from scanplan.robot.fit_marks import renumbered_passes
from scanplan.robot.flown_poses import HALF_TURN, flyable_poses, turned_passes
from scanplan.robot.links import hung, obstacles_for
from scanplan.robot.place import reach_mm
from scanplan.robot.place_weights import sample_poses
from scanplan.robot.placed_arm import PlacedArm
from scanplan.robot.presets import get_robot
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


def view_blocks(traj: Trajectory) -> list[np.ndarray]:
    """(n,) masks: each view's poses (its passes and the moves into them), in order."""
    views = view_records(traj) or (ViewRecord(0, (0.0, 0.0, 1.0), 0, 1 << 30, 0),)
    out = [v.holds(traj.swath) for v in views]
    return [m for m in out if m.any()]


def _judged_poses(traj: Trajectory, block: np.ndarray) -> np.ndarray:
    """The poses a view's (`block`'s) settings are judged on: `SAMPLE_POSES` of its
    scanning poses (of all its poses if it has none)."""
    index = np.flatnonzero(block)
    scan = index[traj.scanning[index]]
    if not len(scan):
        scan = index
    return scan[sample_poses(traj.subset(np.isin(np.arange(len(traj)), scan)), SAMPLE_POSES)]


def _scores(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    axes: ExternalAxes,
    jobs: list[tuple[np.ndarray, np.ndarray]],
) -> list[np.ndarray]:
    """`kept_each`'s scores of the settings `_pick` may choose among (-1 for the others):
    first those with the highest bound (`reach_bound_each`), then those whose bound is
    within NEAR_BEST of the best kept so far; a setting bounded below that keeps less than
    any `_pick` looks at, so the same setting is picked as with every one judged."""
    bounds = reach_bound_each(traj, arm, T_base_part, inv_tcp, axes, jobs)
    scores = [np.full(len(settings), -1.0) for settings, _ in jobs]
    first = [b >= b.max() - 1e-9 if len(b) else b > 0 for b in bounds]
    for chosen in (first, None):
        if chosen is None:  # then all those that may come within NEAR_BEST of the best
            chosen = [
                (b >= max(sc.max(), 0.0) * (1.0 - NEAR_BEST) - 1e-9) & (sc < 0) if len(b) else b > 0
                for b, sc in zip(bounds, scores, strict=True)
            ]
        part = [(settings[m], index) for (settings, index), m in zip(jobs, chosen, strict=True)]
        kept = kept_each(traj, arm, T_base_part, inv_tcp, obstacles, axes, part)
        for sc, m, k in zip(scores, chosen, kept, strict=True):
            sc[m] = k
    return scores


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
    blocks = view_blocks(traj)
    jobs = [(settings, _judged_poses(traj, block)) for block in blocks]
    every = _scores(traj, arm, T_base_part, inv_tcp, obstacles, axes, jobs)
    last = None
    for block, scores in zip(blocks, every, strict=True):
        index = np.flatnonzero(block)
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

    def aiming(self) -> None:
        """None: the axes bring a view round to the arm, wherever it stands."""
        return None

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
        planned, turned = flyable_poses(
            with_axes, arm, T, inv_tcp, obstacles, exact=False, choosing=traj.scanning
        )
        scanning = traj.scanning
        turn = np.isin(
            traj.swath, turned_passes(traj.swath[scanning], planned[scanning], turned[scanning])
        )
        keep = np.where(turn, turned, planned) | ~scanning
        poses = np.where(turn[:, None, None], traj.poses @ HALF_TURN, traj.poses)
        swath = renumbered_passes(traj, keep, traj.swath, np.zeros(len(traj), bool))
        return replace(traj, poses=poses).subset(keep, swath)

    def flown_beyond(self, part: Part, traj: Trajectory, least: int) -> Trajectory | None:
        """`flown`, where it keeps more than `least` scanning poses, else None: judged whole
        (each view is flown at a setting of its own, which one placement does not bound)."""
        flown = self.flown(part, traj)
        return flown if flown.scanning.sum() > least else None


def fitted_axes_record(axes: ExternalAxes, traj: Trajectory) -> dict:
    """What the arm's record holds of the axes: their description, and how far each moves
    over the plan (sum of |Δ|, degrees or mm)."""
    travel = [] if traj.external is None else np.abs(np.diff(traj.external, axis=0)).sum(axis=0)
    return axes.record() | {"travel": [round(float(t), 3) for t in travel]}


__all__ = [
    "PlacedArmOnAxes",
    "candidates",
    "choose_values",
    "fitted_axes_record",
    "hangs",
    "kept",
    "long_side",
    "resolved",
    "view_blocks",
]
