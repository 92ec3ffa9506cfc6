"""Views planned on worker processes (view_workers): the same plan and in-spec set as planned
here, a failing view's error raised where it is taken, and a part pickled for a worker without
its ray engine."""

from __future__ import annotations

import importlib.util
import os
import pickle
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import scanplan.planning.view_workers as view_workers
from helpers import (
    DiesInAWorker,
    Endless,
    FakeArm,
    loopback_cluster,
    overhang_part,
    tcp_server,
)
from scanplan.core.quantities import OVERLAP, UP, ScanSpec
from scanplan.planning.pass_path import ViewRaster
from scanplan.planning.view_choice import choose_views
from scanplan.planning.view_workers import ViewJudge, ViewWorkers, _warm_up
from scanplan.planning.views import SCAN_LEVEL, View, view_axis
from scanplan.rl.planners import make_planner
from scanplan.world.cell import Cell

SPEC = ScanSpec()


def test_a_part_is_pickled_without_its_ray_engine_and_answers_rays_the_same():
    part = overhang_part()
    starts = np.array([[0.0, 0.0, 200.0], [0.0, -240.0, 200.0], [0.0, -400.0, 200.0]])
    down = np.tile([0.0, 0.0, -1.0], (3, 1))
    hits = part.ray_engine.first_hit(starts, down)
    copy = pickle.loads(pickle.dumps(part))
    assert copy._engine is None  # rebuilt where it is used
    again = copy.ray_engine.first_hit(starts, down)
    assert [np.array_equal(a, b) for a, b in zip(hits, again, strict=True)] == [True] * len(hits)


def test_views_planned_on_a_worker_are_those_planned_here():
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    judge = ViewJudge(SPEC, plan, points_per_profile=64)
    side = View.looking_along(view_axis(np.array([0.0, -1.0, 0.0])), 1, scan=SCAN_LEVEL)
    views = [View.looking_along(UP, 0), side]
    here = [judge(part, v) for v in views]
    with ViewWorkers(part, judge, workers=1) as pool:
        futures = [pool.submit(v) for v in views]
        there = [f.result() for f in futures]
    for (plan_here, set_here), (plan_there, set_there) in zip(here, there, strict=True):
        assert np.array_equal(plan_here.traj.poses, plan_there.traj.poses)
        assert plan_here.passes == plan_there.passes
        assert np.array_equal(set_here, set_there)
        assert set_here.any()


def test_a_view_that_sees_nothing_raises_where_it_is_taken():
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    judge = ViewJudge(SPEC, plan, points_per_profile=64)
    # A view of the plate's bottom face, turned to look up at it: nothing of it to scan.
    below = np.flatnonzero(part.mesh.face_normals[:, 2] < -0.99)
    blind = View.looking_along(UP, 1, below)
    for workers in (0, 1):
        with ViewWorkers(part, judge, workers) as pool:
            failed = pool.submit(blind)
            with pytest.raises(ValueError, match="no surface|no valid point|no swath"):
                failed.result()


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_a_view_that_sees_nothing_on_dask_raises_here_and_is_no_error_in_the_worker_log():
    from dask.distributed import Client

    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    judge = ViewJudge(SPEC, plan, points_per_profile=64)
    below = np.flatnonzero(part.mesh.face_normals[:, 2] < -0.99)
    with loopback_cluster() as cluster, Client(cluster) as client:
        with ViewWorkers(part, judge, 0, cluster.scheduler_address) as pool:
            failed = pool.submit(View.looking_along(UP, 1, below))
            with pytest.raises(ValueError, match="no surface|no valid point|no swath"):
                failed.result()
            top, _ = pool.submit(View.looking_along(UP, 0)).result()
        assert len(top.traj.poses)
        logs = [line for worker in client.get_worker_logs().values() for _, line in worker]
    assert logs and not [line for line in logs if "Compute Failed" in line]


def test_a_view_whose_worker_dies_is_planned_here_and_the_rest_too():
    part = overhang_part()
    raster = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    judge = ViewJudge(SPEC, DiesInAWorker(raster), points_per_profile=64)
    side = View.looking_along(view_axis(np.array([0.0, -1.0, 0.0])), 1, scan=SCAN_LEVEL)
    here = judge(part, side)
    with ViewWorkers(part, judge, workers=1) as pool:
        lost = pool.submit(side)
        with pytest.warns(UserWarning, match="view worker stopped"):
            planned, in_spec = lost.result()
        later = pool.submit(side).result()  # no worker left: planned here
    assert np.array_equal(planned.traj.poses, here[0].traj.poses)
    assert np.array_equal(in_spec, here[1]) and np.array_equal(later[1], here[1])


def test_starting_the_workers_after_the_pool_is_gone_is_no_error():
    """The warm-up runs on its own thread: a pool that broke or was shut down before that
    thread ran leaves it nothing to start, not an exception printed from a stray thread."""
    pool = ProcessPoolExecutor(1)
    pool.shutdown()
    _warm_up(pool)  # submit() on this pool raises RuntimeError
    with pytest.raises(RuntimeError):
        pool.submit(int)


def test_leaving_the_workers_stops_the_views_still_running(tmp_path):
    part = overhang_part()
    started = tmp_path / "started"
    judge = ViewJudge(SPEC, Endless(os.getpid(), str(started)), points_per_profile=64)
    with ViewWorkers(part, judge, workers=1) as pool:
        pool.submit(View.looking_along(UP, 0))
        deadline = time.monotonic() + 30.0
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert started.exists()  # the view runs in the worker
        pids = [w.pid for w in pool._pool._processes.values()]
    # Stopped, not waited for (waiting would never end). Their exit codes are not to be
    # trusted (read from the server that forked them, they may come back 255): the
    # processes themselves must be gone, reaped by that server.
    deadline = time.monotonic() + 10.0
    while any(_running(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert pids and not any(_running(pid) for pid in pids)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_a_scheduler_address_that_is_no_scheduler_is_one_line():
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    judge = ViewJudge(SPEC, plan, points_per_profile=64)
    with tcp_server(lambda conn: conn.sendall(b"\xff" * 16)) as address:
        with pytest.raises(ValueError, match=f"^--scheduler {address}: what answers there is not"):
            ViewWorkers(part, judge, 0, address)


class _FliesOnlyFromAbove(FakeArm):
    """An arm that flies a scanning pose only with its beam at most `max_tilt_deg` from
    straight down (its wrist meets a rim lower than that), the rest given up."""

    def __init__(self, max_tilt_deg: float) -> None:
        self.cos = np.cos(np.radians(max_tilt_deg))

    def flown(self, part, traj):
        keep = ~traj.scanning | (traj.poses[:, 2, 2] <= -self.cos)
        return traj if keep.all() else traj.subset(keep)

    def aiming(self) -> None:
        return None  # stands nowhere in particular: no view is slid for it

    def moves_clear(self, part, traj) -> bool:
        return True


def test_a_view_the_arm_cannot_fly_as_planned_is_flown_with_its_beams_raised(monkeypatch):
    """A side view (its beams up to 10 degrees below level) that an arm flies only from a
    few degrees higher: judged with its beams raised within the angle tolerance, it holds
    more in spec than the arm flies of it as planned."""
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    side = View.looking_along(view_axis(np.array([0.0, -1.0, 0.0])), 1, scan=SCAN_LEVEL)
    arm = _FliesOnlyFromAbove(max_tilt_deg=77.0)
    judge = ViewJudge(SPEC, plan, points_per_profile=64, arm=arm)  # type: ignore[arg-type]
    planned, held = judge(part, side)
    assert planned.lean_deg == max(view_workers.LEAN_DEG)
    assert held.any()
    beams = planned.traj.poses[planned.traj.scanning, :3, 2]
    assert np.degrees(np.arccos(-beams[:, 2])).max() <= 80.0 - planned.lean_deg + 1e-6
    free, _ = ViewJudge(SPEC, plan, points_per_profile=64)(part, side)
    assert free.lean_deg == 0.0  # without an arm, views are judged as planned
    monkeypatch.setattr(view_workers, "LEAN_DEG", ())
    as_planned, held_as_planned = judge(part, side)
    assert as_planned.lean_deg == 0.0
    assert held.sum() > held_as_planned.sum()


class _ReachesOnlyNearer(FakeArm):
    """An arm whose shoulder is at `shoulder_at`, that flies a scanning pose of a view
    planned as `planned` (4, 4 each) only where it is on the near side of the plane x =
    `near_x`, or brought at least `least_mm` nearer the shoulder along its laser line."""

    def __init__(
        self, planned: np.ndarray, shoulder_at: np.ndarray, least_mm: float, near_x: float
    ) -> None:
        self.planned, self.shoulder_at = planned, shoulder_at
        self.least_mm, self.near_x = least_mm, near_x

    def aiming(self):
        return self

    def moves_clear(self, part, traj) -> bool:
        return True

    def flown(self, part, traj):
        at = traj.poses[:, :3, 3]
        moved = at - self.planned[:, :3, 3]
        towards = self.shoulder_at - self.planned[:, :3, 3]
        along = np.abs(np.einsum("ij,ij->i", moved, self.planned[:, :3, 0]))
        nearer = (np.einsum("ij,ij->i", moved, towards) > 0) & (along >= self.least_mm)
        keep = ~traj.scanning | nearer | (at[:, 0] <= self.near_x)
        return traj if keep.all() else traj.subset(keep)


def test_a_view_the_arm_reaches_only_part_of_is_flown_with_its_lines_slid_towards_it(
    monkeypatch,
):
    """A side view whose laser line is longer than the wall it holds, flown by an arm that
    reaches its poses past one end of the wall only a little nearer than planned: judged
    with each line slid along itself towards the arm, it holds more in spec than the arm
    flies of it as planned. The top view is not slid."""
    monkeypatch.setattr(view_workers, "LEAN_DEG", ())  # the slide alone
    shares = view_workers.SLIDE_SHARES
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    side = View.looking_along(view_axis(np.array([0.0, -1.0, 0.0])), 1, scan=SCAN_LEVEL)
    free, _ = ViewJudge(SPEC, plan, points_per_profile=64)(part, side)
    assert free.slide_mm == 0.0  # without an arm, views are judged as planned
    poses = free.traj.poses
    shoulder = poses[:, :3, 3].mean(axis=0) + np.array([0.0, -2000.0, 1000.0])
    shortest = min(view_workers.SLIDE_SHARES) * SPEC.sensor.line_width_mm
    arm = _ReachesOnlyNearer(poses, shoulder, 0.5 * shortest, float(np.median(poses[:, 0, 3])))
    judge = ViewJudge(SPEC, plan, points_per_profile=64, arm=arm)  # type: ignore[arg-type]
    slid, held = judge(part, side)
    assert slid.slide_mm in [s * SPEC.sensor.line_width_mm for s in view_workers.SLIDE_SHARES]
    # Each pose moved along its own line by the slide, each pass towards the shoulder.
    moved = slid.traj.poses[:, :3, 3] - poses[:, :3, 3]
    assert np.allclose(np.abs(np.einsum("ij,ij->i", moved, poses[:, :3, 0])), slid.slide_mm)
    assert np.allclose(np.linalg.norm(moved, axis=1), slid.slide_mm)
    nearer = np.einsum("ij,ij->i", moved, shoulder - poses[:, :3, 3])
    for k in np.unique(free.traj.swath):
        assert nearer[free.traj.swath == k].sum() > 0
    assert np.array_equal(slid.traj.poses[:, :3, :3], poses[:, :3, :3])
    # Slid, a move of the view would come into the cell: it is judged as planned.
    arm.moves_clear = lambda part, traj: np.array_equal(traj.poses, poses)
    into_cell, _ = judge(part, side)
    assert into_cell.slide_mm == 0.0
    arm.moves_clear = lambda part, traj: True
    monkeypatch.setattr(view_workers, "SLIDE_SHARES", ())
    as_planned, held_as_planned = judge(part, side)
    assert as_planned.slide_mm == 0.0
    assert held.sum() > held_as_planned.sum()
    top = View.looking_along(UP, 0)
    monkeypatch.setattr(view_workers, "SLIDE_SHARES", shares)
    top_plan, _ = ViewJudge(SPEC, plan, points_per_profile=64)(part, top)
    top_arm = _ReachesOnlyNearer(top_plan.traj.poses, shoulder, 0.5 * shortest, -1e9)
    top_judge = ViewJudge(SPEC, plan, points_per_profile=64, arm=top_arm)  # type: ignore[arg-type]
    # This arm flies only poses slid towards it: the top view, never slid, flies nothing.
    with pytest.raises(ValueError, match="flies nothing"):
        top_judge(part, top)


class _FliesNothingThatMeasures(FakeArm):
    """An arm standing where it flies no scanning pose of any view."""

    T_base_part = np.eye(4)

    def aiming(self) -> None:
        return None

    def moves_clear(self, part, traj) -> bool:
        return True

    def flown(self, part, traj):
        return traj.subset(~traj.scanning)


def test_an_arm_that_flies_nothing_of_any_view_is_said_to_be_out_of_reach_not_the_views():
    part = overhang_part()
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, Cell.around(part))
    with pytest.raises(ValueError, match=r"^the arm placed at --part-pose 0,0,0,0,0,0 flies "):
        choose_views(part, SPEC, plan, arm=_FliesNothingThatMeasures())  # type: ignore[arg-type]
    assert choose_views(part, SPEC, plan).plans  # without the arm its views see the part
