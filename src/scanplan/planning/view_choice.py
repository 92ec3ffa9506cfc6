"""Which views a part is scanned from: the top view, then a lazy greedy set cover of the
surface by candidate views (and views aimed at what they miss), each judged by planning it;
the budget the choice may spend and the rules a view must pass to be kept.
"""

from __future__ import annotations

import math
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass, field, replace

import numpy as np

from scanplan.core.cover import max_cover
from scanplan.core.cycle import view_seconds
from scanplan.core.limits import TooLarge
from scanplan.core.quantities import (
    COVERAGE_TARGET,
    UP,
    VIEW_CHOICE_FAN_POINTS,
    ScanSpec,
)
from scanplan.judging import coverage_spacing_mm
from scanplan.planning.view_budget import Spent, ViewBudget
from scanplan.planning.view_workers import KnownViews, ViewJudge, ViewWorkers
from scanplan.planning.views import (
    SCAN_LEVEL,
    SCAN_UPHILL,
    PlanView,
    View,
    ViewPlan,
    candidate_views,
    missed_views,
)
from scanplan.robot.base import pose_arg
from scanplan.robot.placed_arm import PlacedArm
from scanplan.world.part import Part
from scanplan.world.surface import VisibleSurface, hemisphere_visible_samples, reachable_samples

# Rounds of views aimed at what the chosen views still miss (`views.missed_views`).
MISSED_ROUNDS = 4
# The least a view must add to the in-spec share to be kept, and the most views. At 1 %
# (the earlier "useful amount") the walls of small pockets, each under 1 %, got no view:
# at 0.4 % and 24 views the machined shared parts held 0.79-0.97 of their ceiling; at
# 0.1 % and 80 views the quadrotor and the pocket plate 0.90 and 0.84 against 0.86 and
# 0.83 at 0.2 % and 40 (`benchmarks/compare_views.py`; the quadrotor's thin arms take a
# view per 30° of their round, each under 0.2 %).
MIN_VIEW_GAIN = 0.001
# Below that, a view is still kept if it adds at least MIN_VIEW_GAIN_FLOOR and pays for its
# time in the cycle (`cycle.view_seconds`: its own passes and moves, and a move into it)
# with at least MIN_VIEW_GAIN_PER_S of the surface per second (0.3 % a minute). At 2e-4/s and
# 0.03 % the sheet metal part held 0.91 of its ceiling (0.90 with the full sensor); at
# 5e-5/s and 0.02 % 0.93, its cycle 160 -> 208 s (`benchmarks/compare_views.py`). A strip of
# a thin round wall (the quadrotor's propeller guards, 15° of their round a view) takes a
# second or two; a pocket's wall a few more.
MIN_VIEW_GAIN_PER_S = 5e-5
MIN_VIEW_GAIN_FLOOR = 2e-4
MAX_VIEWS = 150
# The steepest surface a top view holds much of (its passes pitch to walls of at most 60°
# along them and roll to 85° across): a part with more than 1 - COVERAGE_TARGET of its
# surface steeper needs more views.
TOP_VIEW_SLOPE_DEG = 75.0


@dataclass(frozen=True)
class ViewSelection:
    """The views chosen and their estimated in-spec coverage after each (`coverage`);
    `in_spec` the (k,) in-spec sets on the view choice's samples of every view planned,
    the chosen first (in order), then those left out."""

    plans: list[ViewPlan]
    coverage: list[float]
    candidates: int
    in_spec: list[np.ndarray] = field(default_factory=list)
    exact_coverage: float | None = None  # the exact cover's by as many views, for scale
    out_of_time: bool = False  # stopped by the time budget, not by gain or target
    # Every view planned, chosen or not, by key: what a second choice on the same samples
    # need not plan again (`ViewJudge.known`).
    known: KnownViews = field(default_factory=dict)
    # The candidates listed (`candidate_views`; none if the top view was enough): what a
    # second choice on the same part and spec need not list again.
    listed: tuple[View, ...] = ()


def steep_samples(part: Part, samples: VisibleSurface) -> np.ndarray:
    """(k,) bool: the `samples` on faces steeper than `TOP_VIEW_SLOPE_DEG` (their normal as
    far from ±Z: a mesh's winding does not matter here, and turning the normals outwards,
    `surface.oriented_normals`, cost the door's plan 0.3 s)."""
    normal_z = part.ray_engine.face_normals[samples.faces, 2]
    return np.abs(normal_z) < math.cos(math.radians(TOP_VIEW_SLOPE_DEG))


def top_view_may_suffice(steep: np.ndarray, coverage_target: float) -> bool:
    """False when more than 1 - `coverage_target` of the samples are `steep`
    (`steep_samples`): the top view alone cannot reach the target."""
    return bool(steep.sum() <= (1.0 - coverage_target) * len(steep))


def choose_views(
    part: Part,
    spec: ScanSpec,
    plan: PlanView,
    coverage_target: float = COVERAGE_TARGET,
    min_gain: float = MIN_VIEW_GAIN,
    max_views: int = MAX_VIEWS,
    points_per_profile: int = VIEW_CHOICE_FAN_POINTS,
    min_gain_per_s: float = MIN_VIEW_GAIN_PER_S,
    gain_floor: float = MIN_VIEW_GAIN_FLOOR,
    seed: int = 0,
    budget: ViewBudget | None = None,
    scan_level: bool = True,
    workers: int = 0,
    scheduler: str | None = None,
    arm: PlacedArm | None = None,
    known: KnownViews | None = None,
    listed: tuple[View, ...] = (),
) -> ViewSelection:
    """Greedy set cover of the surface a sensor can see from the upper hemisphere: the top
    view first (the paper's raster; on a panel it is all there is; none if nothing to
    inspect faces up), then, while in-spec coverage is below `coverage_target`, the
    candidate view (`candidate_views`) that adds the most, unless it adds less than
    `min_gain` (`MIN_VIEW_GAIN`) and either less than `gain_floor` or less than
    `min_gain_per_s` per second of its time in the cycle (`cycle.view_seconds`); when none
    does, views
    aimed at what a beam could reach and no chosen view holds (`views.missed_views`) join
    the candidates, `MISSED_ROUNDS` times at most, each also scanned level (`View.scan`,
    with `scan_level`: the direction rule left to the raster's 'auto'; with an `arm`, up
    its tilt too), none planned twice.
    A panel whose top view reaches the
    target (the door) stays one view. The exact cover by as many views among all those
    planned (`cover.max_cover`) is computed for scale (`exact_coverage`), not kept.
    Weighing a view's gain against its profiles as well (at least a quarter of the top
    view's in-spec share per profile) was tried and left out: it cost the machined parts
    1-3 points of hemisphere coverage (`benchmarks/compare_views.py`) for views that each
    add more than 1 %.

    Each view's gain is estimated by evaluating its own trajectory alone on the whole part
    with a sub-sampled fan. That is sound because a surface sample's in-spec state depends
    only on the points of one pass (the in-spec test and the density rule look at a point,
    its profile's columns and its neighbouring profiles of the same pass): the in-spec set
    of several views is the union of their in-spec sets on the same (seeded) samples, so the
    set cover is computed exactly on these sets, and a fan of 128 columns finds nearly the
    same samples (the search radius grows with the evaluated column pitch; density is judged on
    the real sensor's columns). Candidates are tried largest possible gain first (their
    region's area not yet in spec) and skipped once that bound is below the best gain found
    (lazy greedy: a view's gain only shrinks as others are chosen). Once the `budget`'s
    candidates are planned (or, only if it sets one, its seconds are past) no further
    candidate is planned: the views chosen by then are kept (`out_of_time`). With `workers`
    (`view_workers.view_worker_count`), candidates are planned on that many processes, each
    the next one the choice would try: the same views, sooner; with `scheduler`, as Dask
    tasks on that cluster. With a placed `arm`, each view is judged by what that arm flies
    of it (`placed_arm.PlacedArm.flown`), so the cover is of what the arm can scan; `known`, the
    views a choice without the arm planned (`ViewSelection.known`), are not planned again,
    and `listed`, the candidates it listed (`ViewSelection.listed`), not listed again."""

    spent = Spent(ViewBudget() if budget is None else budget)
    judge = ViewJudge(spec, plan, points_per_profile, seed, arm, known)
    with ExitStack() as stack:
        # The top view is planned on a thread of its own from the start, beside the samples
        # the views are judged on (`evaluate` draws the same) and the workers' start: a
        # part's first samples take a few tenths of a second (the door's 0.2-0.3 s) while the
        # raster's start leaves a core free. The ray engine is built first, not by both.
        part.ray_engine  # noqa: B018
        beside = stack.enter_context(ThreadPoolExecutor(max_workers=1))
        top_view = beside.submit(judge, part, View.looking_along(UP, 0))
        samples = hemisphere_visible_samples(part, _eval_spacing(spec, points_per_profile), seed)
        rule = _KeepRule(min_gain, gain_floor, min_gain_per_s)
        greedy = _Greedy(part, spec, samples, spent, rule, coverage_target, arm, listed)
        steep = steep_samples(part, samples)
        if workers and scheduler is None and not top_view_may_suffice(steep, coverage_target):
            # The top view cannot be enough: the workers start now and plan, beside it, the
            # candidates with most steep surface on their faces (started after it, they held
            # the quadrotor's and the pocket plate's first candidates 1-2 s back; started
            # for the door, whose top view is enough, they cost about 0.5 s).
            pool = greedy.start_workers(stack, judge, workers)
            guess = [int((m & steep).sum()) for m in greedy.on_faces]
            for i in np.argsort(guess)[::-1][: pool.width]:
                greedy.ask(int(i))
        greedy.take_top(top_view)
        if greedy.target_reached():
            return ViewSelection(
                greedy.plans,
                greedy.coverage,
                0,
                greedy.chosen,
                known=greedy.known(),
                listed=greedy.listed,
            )
        if greedy.pool is None:
            # Started only now: a part whose top view is enough (the door) needs no worker, and
            # starting them anyway took the demo from 55 s to 60 beside its second process.
            greedy.start_workers(stack, judge, workers, scheduler)
        greedy.run(max_views, scan_level)
    # Outside the `with`: the workers are stopped before the exact cover (HiGHS) runs.
    return greedy.selection()


@dataclass(frozen=True)
class _KeepRule:
    """When a view's gain is worth a view (`choose_views`): at least `min_gain`, or at least
    `gain_floor` and `min_gain_per_s` per second of its time in the cycle."""

    min_gain: float
    gain_floor: float
    min_gain_per_s: float

    @property
    def least(self) -> float:
        """The least gain a view may be kept for."""
        return min(self.min_gain, self.gain_floor)


class _Greedy:
    """The lazy greedy choice under way (`choose_views`): the views chosen and the samples
    they hold in spec, the candidates and what is known of each (the bound on its gain,
    asked of the workers, or planned), and the budget spent."""

    def __init__(
        self,
        part: Part,
        spec: ScanSpec,
        samples: VisibleSurface,
        spent: Spent,
        rule: _KeepRule,
        coverage_target: float,
        arm: PlacedArm | None = None,
        listed: tuple[View, ...] = (),
    ) -> None:
        self.part, self.spec, self.samples, self.arm = part, spec, samples, arm
        self.listed = listed
        self.spent, self.rule, self.coverage_target = spent, rule, coverage_target
        self.plans: list[ViewPlan] = []
        self.coverage: list[float] = []
        self.chosen: list[np.ndarray] = []
        self.covered = np.zeros(len(samples.points), bool)
        self.pool: ViewWorkers | None = None
        self.candidates: list[View] = []
        self.on_faces: list[np.ndarray] = []  # the samples on each candidate's faces
        self.tried: set[tuple[bytes, bytes, str]] = set()
        # Asked of the workers, not yet taken: with workers, the next candidates the choice
        # would try (those not planned yet with the largest bounds), `pool.width` of them, so
        # the workers plan ahead of it. Asking for every candidate at once wasted more than it
        # gained (the heightfield's choice took 17 s against 11 in one process, which plans 7).
        self.pending: dict[int, Future[tuple[ViewPlan, np.ndarray]]] = {}
        self.evaluated: dict[int, tuple[ViewPlan, np.ndarray]] = {}
        self.rounds = 0
        self.reachable: np.ndarray | None = None
        # The move into a view: about the part's bounding radius (views are joined around it).
        self.entry_mm = 0.5 * float(np.linalg.norm(part.extents))
        self.seconds_of: dict[int, float] = {}

    def start_workers(
        self, stack: ExitStack, judge: ViewJudge, workers: int, scheduler: str | None = None
    ) -> ViewWorkers:
        """The candidates listed (unless given), then the workers that plan them started (left
        with `stack`)."""
        self.listed = self.listed or tuple(candidate_views(self.part, self.spec))
        self.candidates = list(self.listed)
        # The samples on each candidate's faces: the bound on its gain.
        self.on_faces = [self._on_faces(v) for v in self.candidates]
        self.tried = {v.key() for v in self.candidates}
        self.pool = stack.enter_context(ViewWorkers(self.part, judge, workers, scheduler))
        return self.pool

    def _on_faces(self, view: View) -> np.ndarray:
        return np.isin(self.samples.faces, np.asarray(view.faces))

    def ask(self, i: int) -> None:
        assert self.pool is not None
        self.pending[i] = self.pool.submit(replace(self.candidates[i], index=len(self.plans)))

    def take_top(self, top_view: Future[tuple[ViewPlan, np.ndarray]]) -> None:
        """The top view chosen first; none if nothing to inspect faces up."""
        try:
            top, covered = top_view.result()
            self.plans, self.coverage, self.chosen = [top], [float(covered.mean())], [covered]
            # A copy: `_choose` ORs each view into it, and the top view's own set is kept.
            self.covered = covered.copy()
        except TooLarge:  # the user's numbers, not the view's fault
            raise
        except ValueError:  # nothing to inspect faces up (walls only): the views must see it all
            self.plans, self.coverage, self.chosen = [], [0.0], []

    def target_reached(self) -> bool:
        # Of the surface, not of the visibility ceiling: the sub-sampled fan can read far
        # above the full sensor (NIST sheet metal part: 0.79 against 0.61), and a target
        # under the ceiling then stopped it at 6 views (0.61) where 16 hold 0.77.
        return self.coverage[-1] >= self.coverage_target

    def run(self, max_views: int, scan_level: bool) -> None:
        """Views chosen until the target, `max_views`, or no view worth one is left."""
        while len(self.plans) < max_views and not self.target_reached():
            best = self._best()
            if best is not None:
                self._choose(best)
            elif not self._add_missed(scan_level):
                break

    def _best(self) -> int | None:
        """The candidate adding most that is worth a view, tried largest bound first and
        planned only while its bound can beat the best gain found (a gain only shrinks as
        views are chosen); None if none, or the budget stopped the search first."""
        assert self.pool is not None
        bounds = [float((m & ~self.covered).mean()) for m in self.on_faces]
        order = [int(i) for i in np.argsort(bounds)[::-1] if bounds[i] >= self.rule.least]
        best: tuple[float, int] | None = None
        for rank, i in enumerate(order):
            if best is not None and bounds[i] <= best[0]:
                break
            if i not in self.evaluated:
                # The budget in work first, whether or not a worker has planned it already:
                # which have is a matter of timing, so it must not decide what is taken.
                if self.spent.out_of_work():
                    break
                if i not in self.pending:
                    if self.spent.out_of_time():
                        break
                    self.ask(i)
                elif not self.pending[i].done() and self.spent.out_of_time():
                    break
                # From this one on: those before it were planned, or failed.
                ahead = [j for j in order[rank:] if j not in self.evaluated][: self.pool.width]
                for j in ahead:
                    if j not in self.pending and not self.spent.out_of_time():
                        self.ask(j)
                if not self._take(i):
                    continue
            gain = float((self.evaluated[i][1] & ~self.covered).mean())
            if (best is None or gain > best[0]) and self._worth(gain, i):
                best = (gain, i)
        return None if best is None else best[1]

    def _take(self, i: int) -> bool:
        """Candidate `i`'s plan and in-spec set taken from the workers; False if it failed."""
        self.spent.taken += 1
        try:
            self.evaluated[i] = self.pending.pop(i).result()
        except TooLarge:  # the user's numbers, not the view's fault
            raise
        except ValueError:  # a view whose passes see nothing of the part
            self.on_faces[i] = np.zeros_like(self.on_faces[i])
            return False
        return True

    def _worth(self, gain: float, i: int) -> bool:
        if gain >= self.rule.min_gain:
            return True
        if gain < self.rule.gain_floor:
            return False
        if i not in self.seconds_of:
            self.seconds_of[i] = view_seconds(self.evaluated[i][0].traj, self.spec, self.entry_mm)
        return gain >= self.rule.min_gain_per_s * self.seconds_of[i]

    def _choose(self, i: int) -> None:
        vp, cov = self.evaluated.pop(i)
        self.on_faces[i] = np.zeros_like(self.on_faces[i])
        self.plans.append(replace(vp, view=replace(vp.view, index=len(self.plans))))
        self.covered |= cov
        self.chosen.append(cov)
        self.coverage.append(float(self.covered.mean()))

    def _add_missed(self, scan_level: bool) -> bool:
        """Nothing left among the candidates: new ones aimed at what is still missed
        (`views.missed_views`). False when no round is left, the budget is spent, or every
        view aimed so was planned before."""
        if self.rounds == MISSED_ROUNDS or self.spent.out_of_time():
            return False
        self.rounds += 1
        if self.reachable is None:
            self.reachable = reachable_samples(self.part, self.samples, self.spec.tol_angle_rad)
        missed = self.reachable & ~self.covered
        more = missed_views(
            self.part,
            self.spec,
            self.samples,
            missed,
            int(self.rule.least * len(self.covered)),
            arm=None if self.arm is None else self.arm.aiming(),
        )
        # Each also scanned level: a strip under an overhang or down a pocket is seen
        # only so (the camera beside the laser), but level costs the stepped plate and
        # the quadrotor 7 and 2 points of their ceiling when every view is scanned so.
        # With an arm, also up the tilt: the sensor a quarter turn round, where the wrist
        # may reach what it cannot scanning the other ways (flown in spec: the sheet metal
        # on a UR5e 0.618 -> 0.646, the pocket plate on a KR 6 0.717 -> 0.738; nothing lost
        # on the drone, the quadrotor, the NIST plates or the door).
        if scan_level:
            tilted = [v for v in more if v.level_direction() is not None]
            scans = (SCAN_LEVEL,) if self.arm is None else (SCAN_LEVEL, SCAN_UPHILL)
            more += [replace(v, scan=scan) for scan in scans for v in tilted]
        # A view planned before would add what it added then: nothing worth a view.
        more = [v for v in more if v.key() not in self.tried]
        if not more:
            return False
        self.tried |= {v.key() for v in more}
        self.candidates += more
        self.on_faces += [self._on_faces(v) for v in more]
        return True

    def selection(self) -> ViewSelection:
        if not self.plans and self.arm is not None:
            raise ValueError(
                f"the arm placed at --part-pose {pose_arg(self.arm.T_base_part)} flies nothing "
                f"that measures of any view of part {self.part.name}: from there each pose is "
                "out of its reach or puts a link or the sensor into the cell (give another "
                "--part-pose, a larger arm or a --positioner)"
            )
        if not self.plans:
            raise ValueError(f"no view of part {self.part.name} sees its surface to inspect")
        left_out = [cov for _, cov in self.evaluated.values()]
        exact = None
        if len(self.plans) >= 2:
            # How far greedy is from the exact cover by as many views among all those planned
            # (recorded, not used: a set without the top view first joins worse, and the
            # exact set held less on the quadrotor and the stepped plate when kept).
            try:
                _, exact = max_cover(self.chosen + left_out, len(self.plans))
            except ValueError:  # HiGHS out of time: a figure for scale, not worth failing a plan
                exact = None
        return ViewSelection(
            self.plans,
            self.coverage,
            len(self.candidates),
            self.chosen + left_out,
            exact,
            self.spent.timed_out,
            self.known(),
            self.listed,
        )

    def known(self) -> KnownViews:
        """Every view planned and its in-spec set, by key."""
        judged = [*zip(self.plans, self.chosen, strict=True), *self.evaluated.values()]
        return {vp.view.key(): (vp, cov) for vp, cov in judged}


def _eval_spacing(spec: ScanSpec, points_per_profile: int) -> float:
    """The sample spacing `metrics.evaluate` uses with that fan (the same samples)."""
    return coverage_spacing_mm(spec.sensor.with_points(points_per_profile))
