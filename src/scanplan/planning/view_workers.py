"""Candidate views planned and judged on worker processes, one per core (`ViewWorkers`): the
view choice asks for the next few candidates in the order it would try them, and each worker
holds the part, its ray engine built once, for the whole choice. Passes share one process's
GIL (threads gave the view choice nothing); processes do not.

On one core, or in a process that is itself a worker (a catalogue's part, the demo's second
process), the views are planned in this process, one at a time. With a Dask scheduler
(`plan --scheduler` for one part), they are Dask tasks on its cluster.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import warnings
from collections.abc import Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from multiprocessing import forkserver
from typing import Any

import numpy as np

from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec
from scanplan.core.run import scheduler_client
from scanplan.core.trajectory import Trajectory
from scanplan.judging import in_spec_samples
from scanplan.planning.view_poses import raised_beams, slid_lines
from scanplan.planning.views import PlanView, View, ViewPlan, plan_view
from scanplan.robot.placed_arm import PlacedArm
from scanplan.world.part import Part

# Views kept asked for per worker: one running and one queued behind it, so a worker that
# finishes starts the next at once instead of idling while the choice reads another's result
# (half the views take under 50 ms; the round trip through the choice took 20-40 ms).
TASKS_AHEAD = 2
# A tilted view the arm flies less than this share of the scanning poses of is tried again
# with its beams raised towards straight down by each of `LEAN_DEG` degrees: seen from
# higher up, the wrist and the links clear a rim or the table they met as planned (the
# pocket plate's walls). A wall's view already looks 10 degrees down on it
# (`VIEW_AXIS_MAX_TILT_DEG`), so of its 15 degrees of angle tolerance 5 are left: raised
# 6 degrees, none of the stepped plate's walls held in spec. The top view is not raised
# (raised, the drone's held more on the view choice's fan and less once fitted: 0.909 of
# 0.921 flown on a UR5e, against 0.932).
LEAN_BELOW = 0.9
LEAN_DEG = (2.5, 4.5)
# A view the arm still flies less than `LEAN_BELOW` of is tried again with every pass slid
# along its laser line towards the arm's shoulder by each of these shares of the line's
# width: the line (495 mm at the working distance) is often longer than what its pass
# holds, and the sensor then comes nearer the arm (the stepped plate's walls far from a
# KR 6 on the table: held from the line's end, raised, not from its middle). Tilted views
# only, as for raising: with the top view slid too, the drone on a UR5e and the quadrotor,
# the stepped plate and the sheet metal on a KR 6 flew the same, within 0.001.
SLIDE_SHARES = (0.15, 0.3)

# A view's key (`View.key`) -> its plan and in-spec set, as a view choice judged them.
KnownViews = dict[tuple[bytes, bytes, str], tuple[ViewPlan, np.ndarray]]
# A view judged for an arm: its plan, what the arm flies of it, what that holds in spec
# (None: nothing that measures).
_Judged = tuple[ViewPlan, Trajectory, np.ndarray | None]


@dataclass(frozen=True)
class ViewJudge:
    """A view planned by `plan` (on the part turned into its frame: `views.plan_view`) and
    judged: its in-spec set on the samples of the surface seen from the upper hemisphere
    (`in_spec_samples` with a fan of `points_per_profile` columns and samples drawn with
    `seed`). With an `arm`, what it flies of the view is judged. `known`: views planned
    and judged before on the same samples without the arm (the free choice's), taken as
    they were planned, and as they were judged where the arm flies all of them as
    planned. Picklable when `plan` is."""

    spec: ScanSpec
    plan: PlanView
    points_per_profile: int
    seed: int = 0
    arm: PlacedArm | None = None
    known: KnownViews | None = None

    def __call__(self, part: Part, view: View) -> tuple[ViewPlan, np.ndarray]:
        before = None if self.known is None else self.known.get(view.key())
        if before is None:
            planned = plan_view(part, view, self.plan)
        else:
            planned = replace(before[0], view=replace(before[0].view, index=view.index))
        if self.arm is None:
            return planned, self._held(part, planned.traj)
        # With an arm, what it flies of the view: the choice then picks views it can fly.
        flown = self.arm.flown(part, planned.traj)
        if before is not None and flown is planned.traj:
            return planned, before[1]
        best = (planned, flown, self._held_or_none(part, flown))
        scanning = int(planned.traj.scanning.sum())
        tilted = view.level_direction() is not None
        if tilted and flown.scanning.sum() < LEAN_BELOW * scanning:
            best = self._leaned(part, best)
        if tilted and best[1].scanning.sum() < LEAN_BELOW * scanning:
            best = self._slid(part, best)
        if best[2] is None:  # flown, the view measures nothing
            raise ValueError(f"the arm flies nothing that measures of view {view.index}")
        return best[0], best[2]

    def _leaned(self, part: Part, best: _Judged) -> _Judged:
        """The view with its beams raised by each of `LEAN_DEG` (`raised_beams`), if better
        (`_better`)."""
        planned = best[0]
        for deg in LEAN_DEG:
            poses = raised_beams(planned.traj.poses, self.spec.working_distance_mm, deg)
            raised = replace(planned.traj, poses=poses)
            best = self._better(part, best, replace(planned, traj=raised, lean_deg=deg))
        return best

    def _slid(self, part: Part, best: _Judged) -> _Judged:
        """The view (as planned, or raised if that was kept) with each pass slid along its
        laser line towards the arm's shoulder by each of `SLIDE_SHARES` of the line's width
        (`slid_lines`), if better (`_better`)."""
        assert self.arm is not None
        aiming = self.arm.aiming()
        if aiming is None:  # an arm on external axes stands nowhere in particular
            return best
        chosen = best[0]
        for share in SLIDE_SHARES:
            mm = share * self.spec.sensor.line_width_mm
            poses = slid_lines(chosen.traj.poses, chosen.traj.swath, aiming.shoulder_at, mm)
            slid = replace(chosen.traj, poses=poses)
            best = self._better(part, best, replace(chosen, traj=slid, slide_mm=mm))
        return best

    def _better(self, part: Part, best: _Judged, moved: ViewPlan) -> _Judged:
        """`best`, or the view with its poses `moved` where the arm flies more of those,
        none of its moves comes into the cell so (`flown` judges only the poses that scan),
        and the flown poses hold more in spec."""
        assert self.arm is not None
        flown = self.arm.flown_beyond(part, moved.traj, int(best[1].scanning.sum()))
        if flown is None:
            return best
        if not self.arm.moves_clear(part, moved.traj):
            return best
        held = self._held_or_none(part, flown)
        if held is None or (best[2] is not None and held.sum() <= best[2].sum()):
            return best
        return moved, flown, held

    def _held(self, part: Part, traj: Trajectory) -> np.ndarray:
        context = PlanContext(self.spec, views="auto")
        return in_spec_samples(part, self.spec, traj, self.seed, self.points_per_profile, context)

    def _held_or_none(self, part: Part, traj: Trajectory) -> np.ndarray | None:
        try:
            return self._held(part, traj)
        except ValueError:  # what the arm flies of the view measures nothing
            return None


def view_worker_count() -> int:
    """Worker processes to plan views on: one per core; none (plan here) on one core or in
    a process that is itself a worker, whose parent already keeps the cores busy."""
    if multiprocessing.parent_process() is not None:
        return 0
    cores = os.cpu_count() or 1
    return cores if cores > 1 else 0


def start_worker_server() -> None:
    """Start the server process the view workers are forked from, if not running yet (it
    imports this module once: 1.4 s here, most of it trimesh)."""
    multiprocessing.get_context("forkserver").set_forkserver_preload([__name__])
    forkserver.ensure_running()


class ViewWorkers:
    """`submit(view)`: a future of `judge(part, view)`, run on `workers` worker processes
    in the order submitted (0: here, when submitted), or with `scheduler` (tcp://HOST:PORT)
    as Dask tasks on that cluster, the part and judge sent to each of its workers once.
    `width`: how many views to keep asked for: `TASKS_AHEAD` per worker (one when planned
    here, where asking is planning). Leaving the `with` block drops the views
    not started and stops those running (a cluster's are cancelled)."""

    def __init__(
        self, part: Part, judge: ViewJudge, workers: int, scheduler: str | None = None
    ) -> None:
        self._part, self._judge = part, judge
        self._pool: ProcessPoolExecutor | None = None
        self._client: Any = None
        self.width = TASKS_AHEAD * workers if workers else 1
        if scheduler is not None:
            self._connect(scheduler)
        elif workers:
            # Forked from a fresh server process that has imported this module once, not from
            # this one (it already runs Embree's and the passes' threads), nor spawned: a
            # spawned worker imports numpy, trimesh and Embree while this process waits to
            # hand it the part (1.3 s a worker here).
            start_worker_server()
            self._pool = ProcessPoolExecutor(
                workers,
                mp_context=multiprocessing.get_context("forkserver"),
                initializer=_start_worker,
                initargs=(part, judge),
            )
            # The workers start (about a second before the first submit returns) beside the
            # caller's next work, not in its way.
            self._warm_up = threading.Thread(target=_warm_up, args=(self._pool,), daemon=True)
            self._warm_up.start()

    def __enter__(self) -> ViewWorkers:
        return self

    def _connect(self, scheduler: str) -> None:
        self._cluster = ExitStack()  # closed by __exit__
        self._client = self._cluster.enter_context(scheduler_client(scheduler))
        try:
            threads = sum(self._client.nthreads().values())
            self.width = TASKS_AHEAD * max(threads, 1)
            # Sent once to every worker; each task is given the workers' own copy, whose ray
            # engine is built by the first task there and kept.
            self._state = self._client.scatter((self._part, self._judge), broadcast=True)
        except BaseException:
            self._cluster.close()
            raise

    def __exit__(self, *exc_info: object) -> None:
        if self._pool is not None:
            self._warm_up.join()
            # The views still running are not wanted: their workers are stopped, not waited
            # for (a heightfield's view planned ahead held its choice 2-4 s at the end). The
            # executor cannot stop a running task before Python 3.14: its processes are.
            workers = list((self._pool._processes or {}).values())
            self._pool.shutdown(wait=False, cancel_futures=True)
            for worker in workers:
                worker.terminate()
            for worker in workers:
                worker.join()
        if self._client is not None:
            self._cluster.close()

    def submit(self, view: View) -> Any:
        if self._client is not None:
            return _Raising(self._client.submit(_judge_quietly, self._state, view, pure=False))
        if self._pool is not None:
            try:
                return _OrHere(self._pool.submit(_judge_in_worker, view), self, view)
            except BrokenProcessPool:
                self._lost_workers()
        done: Future[tuple[ViewPlan, np.ndarray]] = Future()
        try:
            done.set_result(self._judge(self._part, view))
        except Exception as exc:  # raised by result(), as a worker's would be
            done.set_exception(exc)
        return done

    def instead(self, view: View) -> tuple[ViewPlan, np.ndarray]:
        """`view` planned here: the worker that had it died."""
        self._lost_workers()
        return self._judge(self._part, view)

    def _lost_workers(self) -> None:
        """A worker died (killed, out of memory): the views left are planned here."""
        if self._pool is not None:
            warnings.warn(
                "a view worker stopped; the views left are planned in this process",
                stacklevel=3,
            )
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None


class _OrHere:
    """A worker's future whose result, if the worker died, is planned here instead."""

    def __init__(self, future: Future, workers: ViewWorkers, view: View) -> None:
        self._future, self._workers, self._view = future, workers, view

    def done(self) -> bool:
        return self._future.done()

    def result(self) -> tuple[ViewPlan, np.ndarray]:
        try:
            return self._future.result()
        except BrokenProcessPool:
            return self._workers.instead(self._view)


class _Raising:
    """A Dask future of `_judge_quietly`, whose returned ValueError `result()` raises."""

    def __init__(self, future: Any) -> None:
        self._future = future

    def done(self) -> bool:
        return bool(self._future.done())

    def result(self) -> tuple[ViewPlan, np.ndarray]:
        out = self._future.result()
        if isinstance(out, ValueError):
            raise out
        return out


def _warm_up(pool: ProcessPoolExecutor) -> None:
    """Start the pool's workers with a task that does nothing."""
    try:
        pool.submit(int)
    except (BrokenProcessPool, RuntimeError):
        # A worker died, or the choice ended, before this thread ran: nothing left to start
        # (an exception here would only be printed from a stray thread).
        pass


# A worker's part and judge, set once when it starts.
_WORKER: tuple[Part, ViewJudge] | None = None


def _start_worker(part: Part, judge: ViewJudge) -> None:
    global _WORKER
    _ignore_ctrl_c()
    _WORKER = (part, judge)


def _judge_in_worker(view: View) -> tuple[ViewPlan, np.ndarray]:
    assert _WORKER is not None
    return _judge_with(_WORKER, view)


def _judge_with(state: tuple[Part, ViewJudge], view: View) -> tuple[ViewPlan, np.ndarray]:
    part, judge = state
    return judge(part, view)


def _judge_quietly(
    state: tuple[Part, ViewJudge], view: View
) -> tuple[ViewPlan, np.ndarray] | ValueError:
    """`_judge_with`, a view's ValueError (it sees nothing, every pose too near) returned, not
    raised: it is an answer, and a Dask worker logs each task that raises as an error with
    its traceback (85 of them for the pocket plate's choice)."""
    try:
        return _judge_with(state, view)
    except ValueError as exc:
        return exc


@contextmanager
def process_beside() -> Iterator[ProcessPoolExecutor | None]:
    """One process, forked from the workers' server, for work a caller runs beside its own
    (a second core's judging while this one fits an arm); None where there are no view
    workers (one core, or in a worker): the caller runs that work itself. A task that has
    not finished when the block is left is waited for; if the process dies (killed, out of
    memory), its futures raise `BrokenProcessPool` and the caller may run the work itself."""
    if not view_worker_count():
        yield None
        return
    start_worker_server()
    context = multiprocessing.get_context("forkserver")
    with ProcessPoolExecutor(1, mp_context=context, initializer=_ignore_ctrl_c) as pool:
        yield pool


def _ignore_ctrl_c() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
