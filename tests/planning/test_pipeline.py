"""Planning a part by views (pipeline.plan_views): the greedy choice raises in-spec coverage and
reduces to the top view on a panel; views are ordered by a short tour and joined by clear
moves; a view no clear move reaches is left out and counted."""

from __future__ import annotations

import json
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

import scanplan.planning.pass_path as pass_path_module
import scanplan.planning.pipeline as pipeline_module
import scanplan.planning.view_choice as view_choice_module
import scanplan.planning.view_joining as view_joining_module
import scanplan.planning.view_workers as view_workers_module
from helpers import (
    HEMISPHERE,
    FakeArm,
    fcl_distance,
    fixture_files,
    overhang_part,
    straight,
)
from scanplan.cli import app
from scanplan.core.context import PlanContext
from scanplan.core.cycle import view_seconds
from scanplan.core.plan_file import read_json, read_trajectory, write_json
from scanplan.core.quantities import COVERAGE_TARGET, OVERLAP, UP, VIEW_CHOICE_FAN_POINTS, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import evaluate
from scanplan.planning.pass_path import ViewRaster, passes_blocked, plan_scan
from scanplan.planning.pipeline import Arm, default_views, plan_views
from scanplan.planning.view_budget import ViewBudget
from scanplan.planning.view_choice import (
    _eval_spacing,
    choose_views,
    steep_samples,
    top_view_may_suffice,
)
from scanplan.planning.view_joining import order_views
from scanplan.rl.planners import make_planner
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.place import best_placement, place
from scanplan.robot.presets import get_robot
from scanplan.world.cell import Cell, planned_cell
from scanplan.world.collision import checker_for
from scanplan.world.part import load_part, part_from_mesh
from scanplan.world.surface import hemisphere_visible_samples

SPEC = ScanSpec()


@pytest.fixture(scope="module")
def housing_top(housing):
    """The housing's plain top raster (geometric planner): (swaths, trajectory)."""
    return plan_scan(housing, SPEC, make_planner("geometric"))


def test_housing_auto_views_raise_in_spec_coverage(housing, housing_top, housing_views, tmp_path):
    part = housing
    _, top = housing_top
    plans, auto = housing_views
    assert len(plans) >= 2
    views = auto.meta["views"]
    assert [v["index"] for v in views] == list(range(len(plans)))
    # Swath indices: one consecutive block per view.
    for v in views:
        scan = auto.swath[auto.scanning]
        in_block = (scan >= v["first_swath"]) & (scan <= v["last_swath"])
        assert in_block.any()
    assert views[0]["axis"] == pytest.approx([0, 0, 1])
    top_cov = evaluate(part, SPEC, top, points_per_profile=256, context=HEMISPHERE)
    auto_cov = evaluate(part, SPEC, auto, points_per_profile=256)  # several views: hemisphere
    assert auto_cov.visible_area_mm2 == pytest.approx(top_cov.visible_area_mm2)
    # The top raster rolls its line onto the 60° walls too (0.67), but only views hold them.
    assert auto_cov.in_spec_coverage >= 0.9
    assert auto_cov.in_spec_coverage > top_cov.in_spec_coverage + 0.2
    # Each added view looks along its axis: its scanning poses' beams point against it (the
    # top view's passes roll onto the walls, so its beams tilt).
    for k, v in enumerate(views[1:], start=1):
        scan = auto.scanning & (auto.swath >= v["first_swath"]) & (auto.swath <= v["last_swath"])
        beams = auto.poses[scan][:, :3, 2]
        assert np.median(beams @ np.array(v["axis"])) < -0.8, k
    # The JSON keeps the views' record.
    write_json(auto, tmp_path / "t.json")
    assert read_json(tmp_path / "t.json").meta["views"] == views


def test_views_top_is_the_plain_top_raster(housing, housing_top):
    swaths, top = housing_top
    plans, joined = plan_views(housing, SPEC, make_planner("geometric"), "top")
    assert len(plans) == 1 and plans[0].passes == len(swaths)
    assert np.allclose(joined.poses, top.poses) and (joined.swath == top.swath).all()


@pytest.mark.slow
def test_door_auto_reduces_to_the_single_top_view(tmp_path):
    out = tmp_path / "door.json"
    result = CliRunner().invoke(app, ["plan", "door", "--views", "auto", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "1 view," in result.stdout
    data = json.loads(out.read_text())
    assert len(data["views"]) == 1 and data["views"][0]["axis"] == pytest.approx([0, 0, 1])
    # The same scan as the plain top raster: same passes, same scanning poses.
    top = tmp_path / "top.csv"
    result = CliRunner().invoke(app, ["plan", "door", "--views", "top", "-o", str(top)])
    assert result.exit_code == 0, result.output
    plain, auto = read_trajectory(top), read_trajectory(out)
    assert data["views"][0]["passes"] == len(np.unique(plain.swath))
    np.testing.assert_allclose(
        auto.poses[auto.scanning][:, :3, 3], plain.poses[plain.scanning][:, :3, 3], atol=1e-3
    )


def test_views_are_ordered_by_a_short_tour_with_the_top_first(housing_views):
    plans, auto = housing_views
    assert np.allclose(plans[0].view.axis, UP)

    def moving(order):
        first = [vp.traj.poses[0, :3, 3] for vp in order]
        last = [vp.traj.poses[-1, :3, 3] for vp in order]
        return sum(float(np.linalg.norm(first[k + 1] - last[k])) for k in range(len(order) - 1))

    ordered = order_views(plans)
    assert np.allclose(ordered[0].view.axis, UP)
    assert sorted(id(vp) for vp in ordered) == sorted(id(vp) for vp in plans)
    # No worse than any order a user could have given: every permutation of the rest.
    from itertools import permutations

    best = min(moving([plans[0], *rest]) for rest in permutations(plans[1:]))
    assert moving(ordered) <= best * 1.2


def test_moves_between_views_keep_the_body_clear(housing, housing_views):
    part = housing
    _, auto = housing_views
    report = checker_for(part, SPEC.sensor).check(auto.poses, SPEC.clearance_mm)
    assert not report.colliding.any()
    # Independently of our checker: python-fcl's own distance for every non-scanning pose.
    for pose in auto.poses[~auto.scanning][::2]:
        assert fcl_distance(part, SPEC.sensor, pose) > 0


def test_default_views_follow_whether_the_planner_rolls():
    assert default_views(make_planner("geometric")) == "auto"
    assert default_views(make_planner("feedback")) == "auto"
    assert default_views(make_planner("fixed")) == "top"
    assert default_views(make_planner("geometric", roll=False)) == "top"
    assert default_views(make_planner("rl")) == "top"  # the shipped v0 policy: pitch only


def test_a_view_no_clear_move_reaches_is_left_out_and_counted(housing, housing_views, monkeypatch):
    part = housing
    plans, _ = housing_views
    assert len(plans) >= 3
    real = view_joining_module.view_transition
    calls = {"n": 0}

    def blocked_once(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 1:
            raise ValueError("no collision-free move between views")
        return real(*args, **kwargs)

    monkeypatch.setattr(view_joining_module, "view_transition", blocked_once)
    kept, joined = view_joining_module.join_views(part, plans, SPEC)
    assert joined.meta["views_unreachable"] == 1
    assert len(kept) == len(plans) - 1 and [v.view.index for v in kept] == list(range(len(kept)))
    assert [v["index"] for v in joined.meta["views"]] == list(range(len(kept)))
    assert np.allclose(kept[1].view.axis, plans[2].view.axis)  # the second view was skipped
    assert (
        checker_for(part, SPEC.sensor).check(joined.poses, SPEC.clearance_mm).colliding.sum() == 0
    )


def test_a_pass_no_clear_move_reaches_is_given_up_and_counted(housing, housing_top, monkeypatch):
    """A piece of pass that no move reaches (neither lifting along +Z nor along the table's
    normal) is given up, counted, instead of failing the whole view; the rest is planned."""
    swaths, _ = housing_top
    assert len(swaths) >= 3
    cell = planned_cell(PlanContext(SPEC), housing)  # the table at the lowest point
    planner = make_planner("geometric")
    whole = pass_path_module.plan_path(housing, SPEC, planner, swaths, cell=cell)
    real = pass_path_module.plan_transition
    calls: list[np.ndarray] = []

    def first_blocked(checker, start, end, clearance_mm, up=UP):
        calls.append(np.asarray(up))
        if len(calls) <= 2:  # both ways to the second pass
            raise ValueError("no collision-free transition")
        return real(checker, start, end, clearance_mm, up=up)

    monkeypatch.setattr(pass_path_module, "plan_transition", first_blocked)
    traj = pass_path_module.plan_path(housing, SPEC, planner, swaths, cell=cell)
    assert cell.table is not None
    assert np.allclose(calls[0], UP) and np.allclose(calls[1], cell.table.normal)
    second = swaths[1].index
    assert not (traj.scanning & (traj.swath == second)).any()
    given_up = int((whole.scanning & (whole.swath == second)).sum())
    assert traj.meta["unreachable_dropped"] == given_up > 0
    assert (traj.scanning & (traj.swath == swaths[2].index)).any()


def test_an_roi_of_walls_only_is_planned_by_side_views():
    # Nothing of a box's +x wall faces up: no top view, a side view sees it, and each
    # profile advances by Δs_opt up the wall (forward is the scan direction, not the
    # horizontal).
    import trimesh

    from scanplan.world.part import part_from_mesh

    mesh = trimesh.creation.box((300.0, 200.0, 100.0))
    mesh.apply_translation((0, 0, 50.0))
    box = part_from_mesh(mesh, "box")
    plans, traj = plan_views(box, SPEC, make_planner("geometric"), "auto", roi="+x:5")
    assert len(plans) >= 1 and all(vp.view.axis[0] > 0.9 for vp in plans)
    m = evaluate(box, SPEC, traj, points_per_profile=256)
    assert m.surface == "roi" and m.in_spec_coverage > 0.3
    assert m.spacing_mean_mm == pytest.approx(SPEC.delta_s_opt_mm, abs=0.02)
    assert m.backward_steps == 0


def test_the_view_choice_keeps_what_it_has_when_its_budget_is_spent(housing, housing_views):
    plans, _ = housing_views
    assert len(plans) >= 3
    planner = make_planner("geometric")
    # One candidate: the top view, and at most the one candidate it could take.
    kept, traj = plan_views(housing, SPEC, planner, "auto", budget=ViewBudget(candidates=1))
    assert 1 <= len(kept) <= 2 and np.allclose(kept[0].view.axis, UP)
    assert traj.meta["view_choice_out_of_budget"] == "1 candidate views"
    assert "view_choice_out_of_budget" not in housing_views[1].meta
    # A choice that needed no candidate (the door's top view reaches the target) does not
    # claim the budget cut it short; nor does a wall-clock limit it never reached.
    door, door_traj = plan_views(
        load_part("door"), SPEC, planner, "auto", budget=ViewBudget(1, seconds=1e-6)
    )
    assert len(door) == 1 and "view_choice_out_of_budget" not in door_traj.meta


def test_a_budget_in_work_chooses_the_same_views_with_or_without_workers(housing):
    # Workers plan ahead of the choice by as many candidates as they are (a machine's cores,
    # or how busy it is, decide how far): the budget counts the candidates the choice takes,
    # so the views are the same however many were asked of the workers.
    cell = planned_cell(PlanContext(SPEC, views="auto"), housing)
    raster = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, cell)
    picks = [
        choose_views(housing, SPEC, raster, budget=ViewBudget(candidates=2), workers=w)
        for w in (0, 2)
    ]
    axes = [[tuple(np.round(vp.view.axis, 9)) for vp in s.plans] for s in picks]
    assert axes[0] == axes[1] and len(axes[0]) >= 2
    for a, b in zip(picks[0].plans, picks[1].plans, strict=True):
        np.testing.assert_array_equal(a.traj.poses, b.traj.poses)
    assert picks[0].out_of_time and picks[1].out_of_time


def test_a_second_choice_plans_no_view_and_lists_no_candidate_the_first_did(housing, monkeypatch):
    # The choice for an arm runs after one without it on the same samples: the views that
    # one planned are taken as planned (and as judged, where the arm flies all of them),
    # and the candidates it listed are not listed again.
    cell = planned_cell(PlanContext(SPEC, views="auto"), housing)
    raster = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, cell)
    first = choose_views(housing, SPEC, raster, budget=ViewBudget(candidates=6), workers=0)
    assert len(first.known) >= len(first.plans) >= 2
    assert len(first.listed) == len(view_choice_module.candidate_views(housing, SPEC)) > 0

    def never(*_):
        raise AssertionError("a view planned or the candidates listed twice")

    monkeypatch.setattr(view_choice_module, "candidate_views", never)
    again = choose_views(
        housing,
        SPEC,
        never,
        budget=ViewBudget(candidates=6),
        workers=0,
        known=first.known,
        listed=first.listed,
    )
    assert [v.view.key() for v in again.plans] == [v.view.key() for v in first.plans]
    assert again.coverage == first.coverage


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [("--view-seconds", "0", "--view-seconds"), ("--view-candidates", "0", "--view-candidates")],
)
def test_the_view_budget_must_be_positive(tmp_path, option, value, message):
    args = ["plan", "door", "-o", str(tmp_path / "p.json"), option, value]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert message in result.output and result.output.count("\n") == 1
    assert not (tmp_path / "p.json").exists()


def test_views_for_what_is_missed_are_also_scanned_level_and_none_is_planned_twice(
    monkeypatch,
):
    planned = []
    plan_view = view_workers_module.plan_view

    def recording(part, view, plan):
        planned.append(view.key())
        return plan_view(part, view, plan)

    # Planned here, one at a time, to see each view planned.
    monkeypatch.setattr(pipeline_module, "view_worker_count", lambda: 0)
    monkeypatch.setattr(view_workers_module, "plan_view", recording)
    part = overhang_part()
    plans, traj = plan_views(part, SPEC, make_planner("geometric"), "auto")
    assert len(planned) == len(set(planned))
    assert any(level for _, _, level in planned)
    # The block's walls under the plate's edge are held: only a level scan holds them.
    m = evaluate(part, SPEC, traj, points_per_profile=128, context=HEMISPHERE)
    assert m.in_spec_of_ceiling > 0.9


def test_below_the_least_gain_a_view_is_kept_only_if_it_pays_for_its_seconds(housing):
    """With no view adding MIN_VIEW_GAIN (1.0 here), a view is kept on its gain per second
    of its time in the cycle: none at an impossible rate; at a rate between those of the
    views kept without one, only views that pay it and add the floor, and fewer of them."""
    cell = planned_cell(PlanContext(SPEC, views="auto"), housing)
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, cell)
    strict = choose_views(housing, SPEC, plan, min_gain=1.0, min_gain_per_s=1.0, workers=0)
    assert len(strict.plans) == 1 and np.allclose(strict.plans[0].view.axis, UP)
    floor = 0.01
    entry_mm = 0.5 * float(np.linalg.norm(housing.extents))

    def rates(selection):
        gains = np.diff(selection.coverage)
        assert np.all(gains >= floor)
        views = selection.plans[1:]
        seconds = [view_seconds(vp.traj, SPEC, entry_mm) for vp in views]
        return gains / np.array(seconds)

    free = choose_views(
        housing, SPEC, plan, min_gain=1.0, min_gain_per_s=0.0, gain_floor=floor, workers=0
    )
    assert len(free.plans) >= 3  # the top and side views
    free_rates = rates(free)
    rate = 0.5 * (free_rates.min() + free_rates.max())
    assert free_rates.min() < rate
    paid = choose_views(
        housing, SPEC, plan, min_gain=1.0, min_gain_per_s=rate, gain_floor=floor, workers=0
    )
    assert 1 < len(paid.plans) < len(free.plans)
    assert np.all(rates(paid) >= rate)


def test_passes_whose_level_poses_all_come_too_near_are_given_up_before_planning(housing):
    """The housing's top passes are clear; under a slab hung where the sensors pass, every
    level pose comes within the clearance, and a region's view is refused with the
    planner's own error before any pass is planned."""
    swaths, _ = plan_scan(housing, SPEC, make_planner("fixed"), raster="nominal")
    assert not passes_blocked(housing, SPEC, swaths, Cell())
    top = float(housing.bounds[1][2])
    slab = trimesh.creation.box((3000.0, 3000.0, 20.0))
    slab.apply_translation((0.0, 0.0, top + SPEC.working_distance_mm))
    hung = Cell(fixtures=(part_from_mesh(slab, "slab"),))
    assert passes_blocked(housing, SPEC, swaths, hung)
    planned = []

    class Recording:
        name, roll, limits = "fixed", False, make_planner("fixed").limits

        def plan(self, part, swath, spec):
            planned.append(swath)
            raise AssertionError("planned")

    with pytest.raises(ValueError, match="every scanning pose on part"):
        plan_scan(housing, SPEC, Recording(), raster="nominal", cell=hung, look_first=True)
    assert planned == []


def test_views_planned_beside_the_top_view_on_workers_are_those_chosen_in_one_process():
    """A part whose top view cannot be enough (its walls) has workers plan candidates while
    the top view is planned here: the same views, in the same order, as one process."""
    part = overhang_part()
    samples = hemisphere_visible_samples(part, _eval_spacing(SPEC, VIEW_CHOICE_FAN_POINTS), 0)
    assert not top_view_may_suffice(steep_samples(part, samples), COVERAGE_TARGET)
    cell = planned_cell(PlanContext(SPEC, views="auto"), part)
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, cell)
    here = choose_views(part, SPEC, plan, workers=0)
    there = choose_views(part, SPEC, plan, workers=2)
    assert len(here.plans) >= 2
    assert [v.view.key() for v in here.plans] == [v.view.key() for v in there.plans]
    assert here.coverage == there.coverage


def test_a_lid_over_part_of_the_plate_is_planned_around_and_judged(plate, tmp_path):
    """A lid 5 mm above 40 % of the plate: the planner's probes find no surface under it, so
    its pass scans the rest (60 % of the length), and the plan's in-spec coverage is the
    plain plan's less the hidden share; the views chosen for it hold what a beam can reach.
    A block beside the plate that hides nothing leaves the plan as it was, pose for pose."""
    lid, beside = fixture_files(tmp_path, plate)
    planner = make_planner("geometric")
    _, bare = plan_views(plate, SPEC, planner, views="top")
    _, by = plan_views(plate, SPEC, planner, views="top", fixtures=[beside])
    assert np.array_equal(bare.poses, by.poses) and np.array_equal(bare.scanning, by.scanning)
    _, lidded = plan_views(plate, SPEC, planner, views="top", fixtures=[lid])
    scanned = lidded.poses[lidded.scanning, 0, 3]
    assert scanned.min() > -60.0 - 5.0 and scanned.max() == pytest.approx(300.0, abs=5.0)
    plain = evaluate(plate, SPEC, bare, points_per_profile=128)
    judged = evaluate(plate, SPEC, lidded, points_per_profile=128)  # in its recorded cell
    assert plain.in_spec_coverage > 0.97
    assert judged.in_spec_coverage == pytest.approx(plain.in_spec_coverage - 0.4, abs=0.02)
    _, auto = plan_views(plate, SPEC, planner, views="auto", fixtures=[lid])
    views = evaluate(plate, SPEC, auto, points_per_profile=128)
    assert views.visibility_ceiling is not None and views.visibility_ceiling < 0.75
    assert views.in_spec_coverage == pytest.approx(views.visibility_ceiling, abs=0.03)


def test_views_for_an_arm_are_chosen_by_what_it_flies():
    part = overhang_part()
    spec = ScanSpec()
    planner = make_planner("geometric")
    straight, angled = parse_pose_arg("0,0,90,0,0,0"), parse_pose_arg("0,0,90,0,30,0")
    arm = Arm("ur5e", straight, brackets=(straight, angled))
    _, traj = plan_views(part, spec, planner, "auto", arm=arm)
    record = traj.meta["robot"]
    # Both brackets placed and judged on the plan made without the arm; the plan is made
    # with the one that flies most of it.
    tried = record["brackets"]
    assert [b["tcp"] for b in tried] == ["0,0,90,0,0,0", "0,0,90,0,30,0"]
    used = [b for b in tried if b["used"]]
    assert len(used) == 1 and used[0]["in_spec_flown"] == max(b["in_spec_flown"] for b in tried)
    assert used[0]["tcp"] == record["tcp"] and used[0]["part_pose"] == record["part_pose"]
    # The plan made without the arm is judged beside what the arm flies of the plan made
    # for it; every pose given up has a cause, and a view's cost is what nothing flown holds.
    assert 0.0 < record["in_spec"] <= record["in_spec_without_robot"] + 1e-9
    assert 0.0 < record["in_spec_free_plan"] <= 1.0
    given_up = {k: sum(v.values()) for k, v in record["given_up_by_cause"].items()}
    assert given_up == record["scanning_poses_given_up"]
    lost = record["in_spec_lost_by_view"]
    assert all(0.0 < v <= record["in_spec_without_robot"] for v in lost.values())
    assert record["flyable"]


def test_a_view_the_arm_left_measuring_nothing_holds_nothing(plate):
    seen = straight(np.arange(0.0, 600.0, 0.5))
    # The second view's pass 5 m up: it measures nothing (in_spec_samples raises for it).
    far = straight(np.arange(0.0, 600.0, 20.0), h_mm=5000.0, swath_index=1)
    traj = Trajectory.concatenate([seen, far], "t")
    views = [
        {"index": k, "axis": [0.0, 0.0, 1.0], "first_swath": k, "last_swath": k, "passes": 1}
        for k in range(2)
    ]
    traj = Trajectory(traj.poses, traj.swath, traj.scanning, meta={"views": views})
    held = pipeline_module._held_by_view(plate, traj, PlanContext(ScanSpec()), {})
    assert list(held) == [0] and held[0].any()


def test_a_view_judged_once_is_not_measured_again(housing, housing_views, monkeypatch):
    # The fit judges each view as planned and as flown: a view the arm left as it was is
    # the same scan, so its in-spec set is taken from the first judgement.
    _, traj = housing_views
    context = PlanContext.from_json_dict(traj.meta["context"], "plan")
    calls: list[int] = []
    real = pipeline_module.in_spec_samples

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline_module, "in_spec_samples", counting)
    judged: dict = {}
    first = pipeline_module._held_by_view(housing, traj, context, judged)
    measured = len(calls)
    assert measured >= 2 and len(first) == measured
    again = pipeline_module._held_by_view(housing, traj, context, judged)
    assert len(calls) == measured  # nothing measured twice
    assert first.keys() == again.keys()
    assert all(np.array_equal(first[k], again[k]) for k in first)
    # A view with one pose fewer is another scan: measured, and only it.
    fewer = traj.subset(np.arange(len(traj)) != int(np.flatnonzero(traj.scanning)[3]))
    pipeline_module._held_by_view(housing, fewer, context, judged)
    assert len(calls) == measured + 1


def test_the_fit_judges_the_unfitted_plan_beside_it_as_it_would_here(
    housing, housing_views, monkeypatch
):
    # What the fit judges of the plan before fitting (each view as planned, the plan made
    # without the arm) runs in a process beside the fit: the record is the one judged here.
    _, traj = housing_views
    context = PlanContext.from_json_dict(traj.meta["context"], "plan")
    tcp = parse_pose_arg("0,0,90,0,0,0")
    arm = Arm("ur5e", tcp, T_base_part=place(traj, "ur5e", tcp).T_base_part)
    here: list[int] = []
    real = pipeline_module._held_share

    def counting(*args):
        here.append(1)
        return real(*args)

    monkeypatch.setattr(pipeline_module, "_held_share", counting)
    monkeypatch.setattr(view_workers_module, "view_worker_count", lambda: 2)
    beside = pipeline_module.fit_arm(housing, traj, arm, context, free=traj).meta["robot"]
    assert here == []  # judged in the other process
    monkeypatch.setattr(view_workers_module, "view_worker_count", lambda: 0)
    alone = pipeline_module.fit_arm(housing, traj, arm, context, free=traj).meta["robot"]
    assert here == [1]
    assert beside == alone
    assert 0.0 < beside["in_spec"] <= beside["in_spec_without_robot"] + 1e-9
    assert 0.0 < beside["in_spec_free_plan"] <= 1.0

    # A process that died (killed, out of memory): the work is done here instead.
    class Dead:
        def submit(self, *args):
            future: Future = Future()
            future.set_exception(BrokenProcessPool("killed"))
            return future

    @contextmanager
    def dead_process():
        yield Dead()

    monkeypatch.setattr(pipeline_module, "process_beside", dead_process)
    again = pipeline_module.fit_arm(housing, traj, arm, context, free=traj).meta["robot"]
    assert again == alone and here == [1, 1]


def test_the_planner_places_the_arm_where_place_does(housing_views):
    _, traj = housing_views
    tcp = parse_pose_arg("0,0,90,0,0,0")
    T, score, evaluated = best_placement(traj, get_robot("ur5e"), tcp)
    placement = place(traj, "ur5e", tcp)
    assert np.array_equal(T, placement.T_base_part)
    assert score == placement.score and evaluated == placement.evaluated > 0


class _FliesAll(FakeArm):
    """An arm standing at -y that reaches every point and flies every view as planned."""

    stands_at = np.array([0.0, -900.0, 0.0])

    def aiming(self) -> _FliesAll:
        return self

    def reaches(self, points: np.ndarray, axis: np.ndarray) -> np.ndarray:
        return np.ones(len(points), bool)

    def flown(self, part, traj: Trajectory) -> Trajectory:
        return traj


def test_views_aimed_at_what_is_missed_are_scanned_up_their_tilt_too_for_an_arm(monkeypatch):
    """The views aimed at what the chosen ones miss join the candidates as the raster's
    rule has them and scanned level; for an arm, scanned up their tilt too (the sensor a
    quarter turn round), one of each per tilted view, and only for an arm."""
    part = overhang_part()
    cell = planned_cell(PlanContext(SPEC, views="auto"), part)
    plan = ViewRaster(SPEC, make_planner("geometric"), "auto", "auto", OVERLAP, cell)
    aimed: list[list[str]] = []
    add_missed = view_choice_module._Greedy._add_missed

    def spied(self, scan_level):
        before = len(self.candidates)
        added = add_missed(self, scan_level)
        aimed.append([v.scan for v in self.candidates[before:]])
        return added

    monkeypatch.setattr(view_choice_module._Greedy, "_add_missed", spied)
    scans = {}
    for name, arm in (("free", None), ("arm", _FliesAll())):
        aimed.clear()
        choose_views(part, SPEC, plan, workers=0, arm=arm)
        scans[name] = [s for added in aimed for s in added]
    free, arm = scans["free"], scans["arm"]
    assert free.count("level") > 0 and "uphill" not in free
    assert arm.count("uphill") == arm.count("level") > 0
    assert arm.count("rule") == free.count("rule")  # the arm flies all: the same views aimed
