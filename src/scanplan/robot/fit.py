"""A plan made flyable by an arm: `fit_to_robot` places the part (or takes its pose), then
gives up the poses the arm cannot reach and splits passes where the arm would flip its
configuration, so that every pass is flown on one branch and a change of configuration
happens only between passes, as a joint move. It says what it gave up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scanplan.core.plan import ViewRecord, view_records
from scanplan.core.trajectory import Trajectory, lead_ins
from scanplan.robot.axes import ExternalAxes, axis_steps, kept, part_poses
from scanplan.robot.base import Robot, pose_arg
from scanplan.robot.fit_marks import FitMarks, entries_of
from scanplan.robot.flown_poses import HALF_TURN, flyable_poses, sensor_clear_both, turned_passes
from scanplan.robot.joint_moves import lift, sensor_swept
from scanplan.robot.links import LinkClearance, LinkMemo, LinkReport, check_links
from scanplan.robot.pass_repairs import CAUSES, flown_back, lifted, lowered
from scanplan.robot.place import Placement, place, reach_mm
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import ReachReport, check_reach
from scanplan.robot.straight_moves import Way, blocked_steps, detours
from scanplan.world.capsule_collision import CellObstacles

# Rounds of dropping and splitting: a piece of a pass may start on another branch than the
# whole pass did, and so show a flip of its own; a few rounds settle it. Passes are flown
# the other way in the first rounds only; after them a round only gives up and splits, so
# the rounds end, but giving up a pass can leave the next one a new joint move into it
# (the quadrotor on a UR5e with a turntable took more than six rounds).
REVERSING_ROUNDS = 6
MAX_ROUNDS = 40
# Times a joint move into one pose is lifted at most (`_gone_round`).
MAX_LIFTS = 3


@dataclass(frozen=True)
class RobotFit:
    """The plan flown by an arm.

    traj: the plan without the poses given up, its passes split at configuration flips
    (swaths renumbered; the views' swath blocks follow). T_base_part: (4, 4) the part's
    pose in the arm's base frame (the placement found, or the one given). report: the
    reach check of `traj` there. given_up: scanning poses given up, per view index;
    moves_given_up: transition poses given up (the arm makes those moves as joint moves);
    splits: passes cut at a configuration flip or a joint swinging inside a pass.
    given_up_by_cause: per view index, the scanning poses given up by cause (`CAUSES`).
    beyond_reach_mm: how much farther from the base axis than the arm reaches the farthest
    pose given up for reach lies (<= 0: within that distance, out of reach at its height or
    orientation); None if none was.
    links: the arm's links along what is kept (None: fitted without a cell). turned: passes
    flown with the sensor turned half a turn about its beam; reversed: passes flown the
    other way, as the joint move into their first pose swept a link into the cell.
    """

    traj: Trajectory
    T_base_part: np.ndarray
    report: ReachReport
    given_up: dict[int, int]
    moves_given_up: int
    splits: int
    placement: Placement | None
    links: LinkReport | None = None
    turned: int = 0
    given_up_by_cause: dict[int, dict[str, int]] = field(default_factory=dict)
    beyond_reach_mm: float | None = None
    reversed: int = 0
    entry: np.ndarray | None = None  # (n,) where the path and each pass are entered
    blocked_lines: int = 0  # straight moves across poses given up the arm cannot fly
    swept_moves: int = 0  # joint moves that bring the sensor body within the clearance

    @property
    def flyable(self) -> bool:
        return (
            self.report.reachable
            and (self.links is None or self.links.clear)
            and not self.blocked_lines
            and not self.swept_moves
        )

    def record(self, tcp: np.ndarray) -> dict:
        """What the plan file records of the arm."""
        return {
            "robot": self.report.model,
            "part_pose": pose_arg(self.T_base_part),
            "tcp": pose_arg(tcp),
            "T_base_part": self.T_base_part.tolist(),
            "T_flange_sensor": np.asarray(tcp).tolist(),
            "scanning_poses_given_up": {str(k): v for k, v in self.given_up.items()},
            "given_up_by_cause": {str(k): v for k, v in self.given_up_by_cause.items()},
            "beyond_reach_mm": (
                None if self.beyond_reach_mm is None else round(self.beyond_reach_mm, 1)
            ),
            "moves_given_up": self.moves_given_up,
            "passes_split": self.splits,
            "passes_turned": self.turned,
            "passes_reversed": self.reversed,
            "reachable": self.report.reachable,
            "links_checked": self.links is not None,
            "flyable": self.flyable,
            "pass_entry_joints_deg": entry_joints_deg(
                entries_of(self.traj, np.zeros(len(self.traj), bool))
                if self.entry is None
                else self.entry,
                self.report.joints,
            ),
        }


def entry_joints_deg(entry: np.ndarray, joints: np.ndarray) -> dict[str, list[float]]:
    """The joints (deg) where the path and each pass are entered (`entry`), by pose index:
    where the program makes its joint moves and the configurations chosen, which every
    reader of the plan follows (`trajectory.pass_entries`, `check_reach`'s `entries`)
    rather than choose again."""
    at = np.flatnonzero(entry & ~np.isnan(joints).any(axis=1))
    return {str(i): np.round(np.degrees(joints[i]), 6).tolist() for i in at}


def fit_to_robot(
    traj: Trajectory,
    robot: str | Path | Robot,
    tcp: np.ndarray,
    T_base_part: np.ndarray | None = None,
    height_range_mm: tuple[float, float] | None = None,
    obstacles: CellObstacles | None = None,
    axes: ExternalAxes | None = None,
) -> RobotFit:
    """`traj` (part frame) made flyable by `robot` with the sensor at `tcp` (`T_flange_sensor`):
    placed by `robot.place.place` unless `T_base_part` is given; poses unreachable or beyond the
    joint limits are given up (a pass goes on after them as a new one) and passes are split
    where the arm flips its configuration, until the reach check of the whole path finds
    neither. First, each pass is turned half a turn about the beam where the arm keeps more of
    its poses that way. In a cell (`obstacles`), poses that put an arm link into the part, a
    fixture or the table are given up too; a pass whose joint move in would sweep a link through
    them is entered at the top of the move leading into it instead (a reconfiguration), then
    flown the other way, and given up if that move does too. Last, where poses of a move were
    given up and the straight line left between the poses either side is not flyable
    (`straight_moves`), the arm goes round: through a pose put in above the line, by two
    straight or two joint moves, where one keeps clear, else by a joint move into the pose
    after; and a joint move that swings the sensor body into the cell is made higher up
    (`joint_moves.lift`), its pass given up where no lift keeps it clear. With external
    `axes`, the part is where each pose's values (`traj.external`) put it."""
    arm = get_robot(robot)
    placement = None
    if T_base_part is None:
        placement = place(traj, arm, tcp, height_range_mm, obstacles=obstacles)
        T_base_part = placement.T_base_part
    inv_tcp = np.linalg.inv(tcp)
    T_all = part_poses(T_base_part, traj.external, axes)
    traj, turned = _turned(traj, arm, T_all, inv_tcp, obstacles)
    m = FitMarks.of(traj)
    splits = 0
    memo: LinkMemo = {}  # the rounds check much the same passes' links again
    arm_cell = (arm, inv_tcp, obstacles, memo)  # what the last checks and ways round need
    for round_ in range(MAX_ROUNDS):
        current = traj.subset(m.keep, m.swath)
        T_now = kept(T_all, m.keep)
        entry = m.entry(current)
        report = _reach(current, arm, T_now, inv_tcp, obstacles, entry, memo)
        index = np.flatnonzero(m.keep)
        why = np.full(len(index), -1)
        why[report.limit_violations] = CAUSES.index("joint limits")
        why[report.unreachable] = CAUSES.index("reach")
        # A joint turning fast inside a pass (a base swing about a singularity) is a joint
        # move: the pass is split there, as at a flip, and the arm moves between the pieces.
        swings = report.pass_jumps
        if report.reachable and obstacles is not None:
            starts = entry | axis_steps(current, axes)
            in_cell = check_links(arm, report.joints, obstacles, T_now, starts, memo=memo)
            moves, raised_now = lifted(current, index, in_cell.moves, m.raised, m.low)
            reverse = round_ < REVERSING_ROUNDS
            traj, reversed_now = flown_back(traj, current, index, moves, why, m.flipped, reverse)
            if reversed_now:
                T_all = part_poses(T_base_part, traj.external, axes)
                m.resumed[m.flipped] = m.descended[m.flipped] = False  # entered afresh
            hit = in_cell.colliding
            why[hit] = CAUSES.index("link in the part") + in_cell.obstacle[hit]
        else:
            reversed_now = raised_now = False
        flips, lowered_now = lowered(current, index, report.config_flips, m.raised, m.low)
        done = not (len(swings) or reversed_now or raised_now or lowered_now)
        if report.reachable and done and (why < 0).all():
            # Settled: the straight lines across what was given up and the sensor body
            # along the joint moves, last.
            lines, swept = _unflown(current, report.joints, entry, T_now, tcp, axes, *arm_cell)
            if not len(lines) and not len(swept):
                break
            traj, m, stuck = _gone_round(
                traj, current, index, lines, swept, report.joints, m, T_all, *arm_cell
            )
            T_all = part_poses(T_base_part, traj.external, axes)
            if not len(stuck):
                continue
            stuck_passes = np.isin(current.swath, current.swath[stuck])
            why[stuck_passes] = CAUSES.index("sensor on a joint move")
        splits += m.give_up(traj, index, why, np.union1d(flips, swings))
    return _fitted(traj, m, T_base_part, T_all, tcp, axes, placement, turned, splits, *arm_cell)


def _fitted(
    traj: Trajectory,
    m: FitMarks,
    T_base_part: np.ndarray,
    T_all: np.ndarray,
    tcp: np.ndarray,
    axes: ExternalAxes | None,
    placement: Placement | None,
    turned: int,
    splits: int,
    arm: Robot,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    memo: LinkMemo,
) -> RobotFit:
    """What a fit's last round leaves (`m` on `traj`, the part at `T_all`): the plan kept,
    what was given up and why, and the verdict on it as `export` will check it."""
    beyond_mm = beyond_reach_mm(traj, arm, T_all, inv_tcp, m.cause)
    given_up, by_cause = _given_up_by_view(traj, m.keep, m.cause)
    reversed_passes = len(np.unique(m.swath[m.flipped & m.keep & traj.scanning]))
    fitted = traj.subset(m.keep, m.swath)
    if not fitted.scanning.any():
        raise ValueError(f"{arm.name} reaches no scanning pose of this plan from this placement")
    fitted = replace(fitted, meta=fitted.meta | {"views": _views(traj, m.swath, m.keep)})
    # The verdict on what is kept, as `export` will check it (after the last round too).
    entry = m.entry(fitted)
    T_kept = kept(T_all, m.keep)
    report = _reach(fitted, arm, T_kept, inv_tcp, obstacles, entry, memo)
    cell = (arm, inv_tcp, obstacles, memo)
    blocked, swept = _unflown(fitted, report.joints, entry, T_kept, tcp, axes, *cell)
    links = None
    if obstacles is not None:
        starts = entry | axis_steps(fitted, axes)
        links = check_links(arm, report.joints, obstacles, T_kept, starts, memo=memo)
    return RobotFit(
        fitted,
        T_base_part,
        report,
        given_up,
        int((~m.keep & ~traj.scanning).sum()),
        splits,
        placement,
        links,
        turned,
        by_cause,
        beyond_mm,
        reversed_passes,
        entry=entry,
        blocked_lines=len(blocked),
        swept_moves=len(swept),
    )


def _reach(
    traj: Trajectory,
    arm: Robot,
    T_now: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    entry: np.ndarray,
    memo: LinkMemo | None = None,
) -> ReachReport:
    """The reach check of `traj` with the part at `T_now`, each pass entered where `entry`
    says on a configuration whose links keep clear of the cell (`obstacles`), if given."""
    return check_reach(
        T_now @ traj.poses @ inv_tcp,
        arm,
        swath=traj.swath,
        scanning=traj.scanning,
        cell=None if obstacles is None else LinkClearance(arm, obstacles, T_now, memo),
        entry=entry,
    )


def _given_up_by_view(
    traj: Trajectory, keep: np.ndarray, cause: np.ndarray
) -> tuple[dict[int, int], dict[int, dict[str, int]]]:
    """The scanning poses of `traj` not in `keep`, counted per view, and per view by
    `cause` (an index into CAUSES per pose)."""
    given_up: dict[int, int] = {}
    by_cause: dict[int, dict[str, int]] = {}
    lost = ~keep & traj.scanning
    for view in view_records(traj) or (ViewRecord(0, (0.0, 0.0, 1.0), 0, 1 << 30, 0),):
        in_view = lost & view.holds(traj.swath)
        if (count := int(in_view.sum())) > 0:
            given_up[view.index] = count
            causes = np.bincount(cause[in_view], minlength=len(CAUSES))
            by_cause[view.index] = {CAUSES[k]: int(c) for k, c in enumerate(causes) if c}
    return given_up, by_cause


def beyond_reach_mm(
    traj: Trajectory, arm: Robot, T_all: np.ndarray, inv_tcp: np.ndarray, cause: np.ndarray
) -> float | None:
    """How much farther from the base axis than the arm reaches the farthest scanning pose
    given up for reach lies (`T_all`: the part's pose, or one per pose); None if none was."""
    far = (cause == CAUSES.index("reach")) & traj.scanning
    if not far.any():
        return None
    flange_xy = (kept(T_all, far) @ traj.poses[far] @ inv_tcp)[:, :2, 3]
    return float(np.hypot(*flange_xy.T).max()) - reach_mm(arm)[0]


def _unflown(
    traj: Trajectory,
    joints: np.ndarray,
    entry: np.ndarray,
    T_now: np.ndarray,
    tcp: np.ndarray,
    axes: ExternalAxes | None,
    arm: Robot,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    memo: LinkMemo,
) -> tuple[np.ndarray, np.ndarray]:
    """Of `traj` flown on `joints`, entered where `entry` says (the part at `T_now`), the
    poses reached by a straight move across poses given up the arm cannot fly
    (`straight_moves.blocked_steps`), and, in a cell, those reached by a joint move (a
    turntable's too) that brings the sensor body within its clearance
    (`joint_moves.sensor_swept`)."""
    lines = blocked_steps(arm, traj, T_now, inv_tcp, joints, entry, obstacles, memo)
    if obstacles is None:
        return lines, np.zeros(0, np.int64)
    jointed = entry | axis_steps(traj, axes)
    return lines, sensor_swept(arm, joints, jointed, T_now, tcp, obstacles)


def _gone_round(
    traj: Trajectory,
    current: Trajectory,
    index: np.ndarray,
    lines: np.ndarray,
    swept: np.ndarray,
    joints: np.ndarray,
    m: FitMarks,
    T_all: np.ndarray,
    arm: Robot,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
    memo: LinkMemo,
) -> tuple[Trajectory, FitMarks, np.ndarray]:
    """The straight moves into poses `lines` and the joint moves into poses `swept` of
    `current` (the kept poses of `traj`, at `index`; `joints` the arm's along them) the arm
    cannot fly, each gone round. A straight one through a pose put in above it
    (`straight_moves.detours`, in a cell, the part where one pose puts it), else by a joint
    move into its end; a joint move lifted (`joint_moves.lift`), where the part stands
    still over it, up to `MAX_LIFTS` times into one pose (a lift changes the branches the
    arm flies on after it, so a move lifted before may need it again). Returns also the joint moves
    nothing clears (whose passes the caller gives up): then nothing is put in."""
    ways: dict[int, Way] = {}
    stuck = []
    T_now = kept(T_all, m.keep)
    for i in swept:
        still = T_now.ndim == 2 or np.array_equal(T_now[i - 1], T_now[i])
        T = None if not still else T_now if T_now.ndim == 2 else T_now[i]
        way = None
        if obstacles is not None and T is not None and m.lifts[index[i]] < MAX_LIFTS:
            a, b = current.poses[i - 1 : i + 1]
            way = lift(arm, T, inv_tcp, a, b, joints[i - 1], joints[i], obstacles, memo)
        if way is None:
            stuck.append(int(i))
        else:
            ways[int(index[i])] = way
    if stuck:
        return traj, m, np.array(stuck, np.int64)
    m.lifts[list(ways)] += 1
    # A line's end is reached by a joint move unless a way round is found (also the end of
    # a lift's straight move down the arm cannot fly from where the reach check enters it).
    m.resumed[index[lines]] = True
    m.descended[index[lines]] = False
    if obstacles is not None and traj.external is None and T_all.ndim == 2:
        found = detours(current, lines, joints, arm, T_all, inv_tcp, obstacles, memo)
        ways |= {int(index[i]): way for i, way in found.items()}
    traj, m = m.with_ways(traj, ways)
    return traj, m, np.zeros(0, np.int64)


def _turned(
    traj: Trajectory,
    arm: Robot,
    T_base_part: np.ndarray,
    inv_tcp: np.ndarray,
    obstacles: CellObstacles | None,
) -> tuple[Trajectory, int]:
    """`traj` with each pass (and the move into it, which carries its swath index) turned
    half a turn about the beam where more of its poses are reachable and clear that way,
    and how many were. Where the move into such a pass, turned, would bring the body (not
    symmetric about the beam) into the cell where it was clear (a move down to a wall view
    beside the table), the move is flown as planned and the arm turns the sensor in the
    joint move into the pass; a pass whose own moves would, is not turned."""
    sensor_ok = None if obstacles is None else sensor_clear_both(traj.poses, obstacles)
    planned, turned = flyable_poses(
        traj, arm, T_base_part, inv_tcp, obstacles, sensor_ok=sensor_ok, choosing=traj.scanning
    )
    scanning = traj.scanning
    better = turned_passes(traj.swath[scanning], planned[scanning], turned[scanning])
    lead = lead_ins(traj)
    as_planned = np.zeros(len(traj), bool)  # moves into turned passes left as planned
    if sensor_ok is not None and len(better):
        spoiled = ~scanning & sensor_ok[0] & ~sensor_ok[1]
        better = np.setdiff1d(better, traj.swath[spoiled & ~lead])
        as_planned = lead & np.isin(traj.swath, traj.swath[spoiled & lead])
    if not len(better):
        return traj, 0
    turn = np.isin(traj.swath, better) & ~as_planned
    poses = np.where(turn[:, None, None], traj.poses @ HALF_TURN, traj.poses)
    return replace(traj, poses=poses), len(better)


def _views(traj: Trajectory, swath: np.ndarray, keep: np.ndarray) -> list[dict]:
    """The views' records with their swath blocks in the renumbered passes."""
    out = []
    for view in view_records(traj):
        kept = view.holds(traj.swath) & keep
        if not kept.any():
            continue
        first, last = int(swath[kept].min()), int(swath[kept].max())
        out.append(
            view.record | {"first_swath": first, "last_swath": last, "passes": last - first + 1}
        )
    return out
