"""Closed-loop robustness trials (scanplan.jobs.trials): with no perturbation the controller flies
the nominal plan again (the nominal figure exactly); on a part that is not where the CAD says
it follows the part the open-loop replay misses; seeded runs repeat, worker processes and a
Dask cluster give the serial numbers; a plan of several views runs every view in its frame;
only feedback and rl plans are taken; a plan fitted to an arm is flown within the arm's reach."""

from __future__ import annotations

import functools
import importlib.util
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
import trimesh

import scanplan.planning.pipeline as pipeline
from helpers import fixture_files, loopback_cluster, recorded_trajectory
from scanplan.core.context import recorded
from scanplan.core.limits import TooLarge
from scanplan.core.plan_file import read_csv, read_json, write_csv, write_json
from scanplan.core.quantities import ScanSpec
from scanplan.jobs.trials import (
    closed_loop_robustness,
    closed_loop_tasks,
    controller_tasks,
    fly_trial,
    plan_swaths_of,
    plan_views_of,
)
from scanplan.judging import SurfaceState, evaluate, robustness, trial_tasks
from scanplan.planning.pipeline import Arm, plan_views
from scanplan.planning.planners import FeedbackPlanner, GeometricPlanner
from scanplan.planning.view_choice import choose_views
from scanplan.robot import check_reach
from scanplan.robot.export import parse_pose_arg
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import part_from_mesh
from scanplan.world.parts import heightfield_solid

SPEC = ScanSpec()
POINTS = 128


@pytest.fixture(scope="module")
def bumpy():
    """A 400 x 160 plate with a smooth bump 30 mm high across its middle (faces of 10 mm)."""
    box = trimesh.creation.box((400.0, 160.0, 10.0))
    box.apply_translation((0, 0, -5.0))
    v, f = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 10.0)
    top = v[:, 2] > -1e-6
    v[top, 2] += 30.0 * np.exp(-((v[top, 0] / 60.0) ** 2))
    return part_from_mesh(trimesh.Trimesh(v, f), "bump")


@pytest.fixture(scope="module")
def feedback_plan(bumpy, tmp_path_factory):
    """The bump planned by the pitch-only feedback controller (one top view), read back from
    its file as evaluate reads it."""
    _, traj = plan_views(bumpy, SPEC, FeedbackPlanner(), "top")
    path = tmp_path_factory.mktemp("plans") / "feedback.json"
    write_json(traj, path)
    return read_json(path)


@pytest.fixture(scope="module")
def ramp():
    """A 300 x 160 block, 10 mm high up to x = 0, then a 70° ramp to 50 mm and a flat top."""
    xs = np.r_[np.arange(-150, 0.1, 10), np.arange(3, 15.1, 3), np.arange(25, 150.1, 10)]
    z = np.interp(xs, [-150, 0, 15, 150], [10, 10, 50, 50])
    ys = np.arange(-80, 80.1, 10)
    return part_from_mesh(heightfield_solid(xs, ys, np.tile(z, (len(ys), 1))), "ramp")


@pytest.fixture(scope="module")
def two_views(ramp, tmp_path_factory):
    """The ramp's top (its sides left out) planned by feedback with roll and --views auto:
    a top view and one tilted 80° towards +x; read back from its file. Views adding less
    than MIN_VIEW_GAIN are left out (no per-second rule), so there are just these two."""
    choose = functools.partial(choose_views, min_gain_per_s=math.inf)
    with pytest.MonkeyPatch.context() as patch:
        # Where `plan_views` looks it up.
        patch.setattr(pipeline, "choose_views", choose)
        _, traj = plan_views(
            ramp, SPEC, FeedbackPlanner(roll=True), "auto", roi="box:-145,-75,5,145,75,60"
        )
    path = tmp_path_factory.mktemp("plans") / "two_views.json"
    write_json(traj, path)
    return read_json(path)


def _closed(part, traj, text, trials=2, seed=0, run=map):
    model = Perturbation.parse(text)
    tasks = closed_loop_tasks(part, traj, recorded(traj, SPEC), model, trials, seed, POINTS)
    return closed_loop_robustness(tasks, run)


def _open(part, traj, text, trials=2, seed=0):
    model = Perturbation.parse(text)
    context = recorded(traj, SPEC)
    return robustness(trial_tasks(part, SPEC, traj, model, trials, seed, POINTS, context=context))


def test_the_plan_records_its_pass_lines(bumpy, feedback_plan, tmp_path):
    swaths = plan_swaths_of(feedback_plan, "plan")
    write_csv(feedback_plan, tmp_path / "plan.csv")  # the CSV carries them as exactly
    from_csv = plan_swaths_of(read_csv(tmp_path / "plan.csv"), "plan.csv")
    for a, b in zip(swaths, from_csv, strict=True):
        assert a.index == b.index and np.array_equal(a.start_mm, b.start_mm)
        assert np.array_equal(a.u, b.u) and np.array_equal(a.v, b.v)
    assert [sw.index for sw in swaths] == sorted(set(feedback_plan.swath.tolist()))
    # Each pass's poses lie on its line: x_s along v, the sensor over the line's start.
    for sw in swaths:
        poses = feedback_plan.poses[feedback_plan.scanning & (feedback_plan.swath == sw.index)]
        assert np.allclose(poses[:, :3, 0] @ sw.v, 1.0)
        assert np.allclose((poses[:, :3, 3] - sw.start_mm) @ sw.v, 0.0, atol=1e-6)


def test_zero_perturbation_is_the_nominal_figure_exactly(bumpy, feedback_plan):
    nominal = evaluate(bumpy, SPEC, feedback_plan, points_per_profile=POINTS, ceiling=False)
    zero = _closed(bumpy, feedback_plan, "place:0mm,0deg;warp:0mm@200mm", trials=1)
    assert 0.3 < nominal.in_spec_coverage < 1.0
    assert list(zero.per_trial) == [nominal.in_spec_coverage]
    assert zero.closed_loop and zero.to_json_dict()["loop"] == "closed"


def test_the_closed_loop_follows_a_displaced_part_the_replay_misses(bumpy, feedback_plan):
    # Trial 0 of seed 4 lifts the part by 25 mm, twice the 12.5 mm depth tolerance: the plan
    # replayed scans it out of spec, the controller measures the lift and follows it.
    text = "place:15mm,1deg"
    trial = Perturbation.parse(text).trial(4, 0)
    assert trial.place_t_mm[2] > 20.0
    closed = _closed(bumpy, feedback_plan, text, trials=1, seed=4)
    replay = _open(bumpy, feedback_plan, text, trials=1, seed=4)
    nominal = _open(bumpy, feedback_plan, "path:0mm", trials=1).mean
    assert replay.mean < 0.5 * nominal
    assert closed.mean > 0.9 * nominal


def test_seeded_runs_repeat_and_workers_give_the_serial_numbers(bumpy, feedback_plan):
    text = "place:5mm,2deg;warp:1mm@100mm"
    a = _closed(bumpy, feedback_plan, text, seed=1)
    with ProcessPoolExecutor(2) as pool:
        b = _closed(bumpy, feedback_plan, text, seed=1, run=pool.map)
    assert np.array_equal(a.per_trial, b.per_trial)
    assert np.array_equal(a.in_spec_share, b.in_spec_share)


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_a_loopback_dask_cluster_gives_the_local_numbers(bumpy, feedback_plan):
    from scanplan.core.run import task_runner as trial_runner  # what evaluate --scheduler runs

    text = "place:5mm,2deg;path:0.2mm"
    with (
        loopback_cluster() as cluster,
        trial_runner(cluster.scheduler_address, 1) as run,
    ):
        on_dask = _closed(bumpy, feedback_plan, text, trials=1, run=run)
    assert np.array_equal(on_dask.per_trial, _closed(bumpy, feedback_plan, text, 1).per_trial)


def test_open_loop_and_old_plans_are_refused(bumpy, feedback_plan):
    _, geometric = plan_views(bumpy, SPEC, GeometricPlanner(), "top")
    model = Perturbation.parse("place:1mm")
    with pytest.raises(ValueError, match="made by geometric"):
        closed_loop_tasks(bumpy, geometric, recorded(geometric, SPEC), model, 1)
    context = recorded(feedback_plan, SPEC)
    two = replace(
        feedback_plan, meta=feedback_plan.meta | {"views": 2 * feedback_plan.meta["views"]}
    )
    with pytest.raises(ValueError, match="has 2 views"):  # a robot-side loop takes one frame
        plan_swaths_of(two, "plan")
    # An older plan's view record: its axis and passes, not its pass lines.
    view = {k: v for k, v in feedback_plan.meta["views"][0].items() if k != "swaths"}
    old = replace(feedback_plan, meta=feedback_plan.meta | {"views": [view]})
    with pytest.raises(ValueError, match="does not record its pass lines"):
        closed_loop_tasks(bumpy, old, context, model, 1)


def test_an_rl_plan_runs_its_policy_in_the_loop(bumpy, tmp_path):
    from scanplan.rl.planner import RLPlanner

    _, traj = plan_views(bumpy, SPEC, RLPlanner.default(), "top")
    write_json(traj, tmp_path / "rl.json")
    plan = read_json(tmp_path / "rl.json")
    nominal = evaluate(bumpy, SPEC, plan, points_per_profile=POINTS, ceiling=False)
    zero = _closed(bumpy, plan, "place:0mm", trials=1)
    assert list(zero.per_trial) == [nominal.in_spec_coverage]
    with pytest.raises(ValueError, match="does not roll; policy .* does"):
        closed_loop_tasks(
            bumpy, plan, recorded(plan, SPEC), Perturbation.parse("place:1mm"), 1, policy="v1"
        )


def test_every_view_of_a_two_view_plan_runs_closed_loop_nominal_exactly(ramp, two_views):
    views = plan_views_of(two_views, "plan")
    assert len(views) == 2
    assert np.allclose(views[0].view.axis, (0, 0, 1))
    assert views[1].view.axis[2] < 0.5  # tilted 80°: its lines lie in its own frame
    context = recorded(two_views, SPEC)
    nominal = evaluate(
        ramp, SPEC, two_views, points_per_profile=POINTS, ceiling=False, context=context
    )
    zero = _closed(ramp, two_views, "place:0mm,0deg;warp:0mm@200mm", trials=1)
    assert 0.5 < nominal.in_spec_coverage < 1.0
    assert list(zero.per_trial) == [nominal.in_spec_coverage]
    assert nominal.coverage_map is not None
    in_spec = nominal.coverage_map.state == SurfaceState.IN_SPEC
    assert np.array_equal(zero.in_spec_share == 1.0, in_spec)  # sample by sample


def test_each_view_follows_a_lifted_part_the_replay_misses(ramp, two_views):
    # Trial 0 of seed 4 lifts the part by 25 mm: the tilted view's controller must follow it
    # in its own frame too, so the samples only it holds in the nominal plan stay in spec.
    context = recorded(two_views, SPEC)
    nominal = evaluate(
        ramp, SPEC, two_views, points_per_profile=POINTS, ceiling=False, context=context
    )
    tilted = two_views.meta["views"][1]
    top = (two_views.swath < tilted["first_swath"]) | (two_views.swath > tilted["last_swath"])
    top_only = replace(
        two_views,
        poses=two_views.poses[top],
        swath=two_views.swath[top],
        scanning=two_views.scanning[top],
    )
    alone = evaluate(
        ramp, SPEC, top_only, points_per_profile=POINTS, ceiling=False, context=context
    )
    assert nominal.coverage_map is not None and alone.coverage_map is not None
    only_tilted = (nominal.coverage_map.state == SurfaceState.IN_SPEC) & (
        alone.coverage_map.state != SurfaceState.IN_SPEC
    )
    assert only_tilted.mean() > 0.05
    closed = _closed(ramp, two_views, "place:15mm,1deg", trials=1, seed=4)
    replay = _open(ramp, two_views, "place:15mm,1deg", trials=1, seed=4)
    assert replay.mean < 0.2 * nominal.in_spec_coverage
    assert closed.mean > 0.9 * nominal.in_spec_coverage
    assert (
        closed.in_spec_share[only_tilted].mean()
        > 0.7
        > 0.2
        > replay.in_spec_share[only_tilted].mean()
    )


def test_a_two_view_closed_loop_repeats_seeded(ramp, two_views):
    text = "place:5mm,2deg;warp:1mm@100mm"
    a = _closed(ramp, two_views, text, seed=1)
    b = _closed(ramp, two_views, text, seed=1)
    assert np.array_equal(a.per_trial, b.per_trial)
    assert np.array_equal(a.in_spec_share, b.in_spec_share)
    assert not np.array_equal(a.per_trial, _closed(ramp, two_views, text, seed=2).per_trial)


def test_each_tilted_view_records_its_region_and_is_flown_on_it(ramp, two_views):
    tilted = two_views.meta["views"][1]
    assert "region" not in two_views.meta["views"][0]  # the top view: the whole surface
    views = plan_views_of(two_views, "plan", len(ramp.mesh.faces))
    faces = views[1].view.faces
    assert faces is not None and 0 < len(faces) < len(ramp.mesh.faces)
    # The region is the surface the view was planned for: faces facing its axis.
    normals = np.asarray(ramp.mesh.face_normals)[faces]
    assert (normals @ views[1].view.axis).min() > 0.5
    assert tilted["region"]["faces"] == len(ramp.mesh.faces)
    with pytest.raises(ValueError, match=r"views\[1\]: the view's region is of a part of"):
        plan_views_of(two_views, "plan", len(ramp.mesh.faces) + 1)


def test_a_look_ahead_policy_flies_tilted_views_on_their_regions(ramp, two_views, tmp_path):
    from helpers import tiny_config
    from scanplan.rl.learn.train import train
    from scanplan.rl.planner import RLPlanner

    env = {"fan_points": 64, "noise": False, "segment_mm": (20.0, 40.0), "lookahead": True}
    train(tiny_config(tmp_path / "ahead", env=env | {"use_position": False}))
    ahead = RLPlanner.from_file(tmp_path / "ahead")
    context = recorded(two_views, SPEC)
    zero = Perturbation.parse("place:0mm")
    tasks = controller_tasks(ramp, two_views, context, ahead, zero, 1, 0, POINTS)
    flown = fly_trial(tasks[0])
    assert flown is not None  # both views flown, none lost
    assert set(np.unique(flown.swath[flown.scanning])) == set(
        np.unique(two_views.swath[two_views.scanning])
    )
    # A plan from before regions were recorded: the look-ahead could not probe as planned.
    old = replace(
        two_views,
        meta=two_views.meta
        | {
            "views": [
                {k: v for k, v in r.items() if k != "region"} for r in two_views.meta["views"]
            ]
        },
    )
    with pytest.raises(ValueError, match="looks ahead on each view's region, which plan does not"):
        controller_tasks(ramp, old, context, ahead, zero, 1, 0, POINTS, where="plan")


def test_a_view_the_loop_cannot_join_is_lost_for_the_trial(ramp, two_views, monkeypatch):
    import scanplan.jobs.trials as trials

    def no_clear_move_in_tilted_views(part, spec, planner, swaths, cell=None):
        if swaths[0].index >= two_views.meta["views"][1]["first_swath"]:
            raise ValueError("no collision-free transition")
        return plan_path(part, spec, planner, swaths, cell=cell)

    plan_path = trials.plan_path
    monkeypatch.setattr(trials, "plan_path", no_clear_move_in_tilted_views)
    tilted = two_views.meta["views"][1]
    top = (two_views.swath < tilted["first_swath"]) | (two_views.swath > tilted["last_swath"])
    top_only = replace(
        two_views,
        poses=two_views.poses[top],
        swath=two_views.swath[top],
        scanning=two_views.scanning[top],
    )
    context = recorded(two_views, SPEC)
    alone = evaluate(
        ramp, SPEC, top_only, points_per_profile=POINTS, ceiling=False, context=context
    )
    with pytest.warns(UserWarning, match="trial 0: view 1 lost: no collision-free transition"):
        zero = _closed(ramp, two_views, "place:0mm", trials=1)
    assert list(zero.per_trial) == [alone.in_spec_coverage]


def test_trials_in_a_cell_with_a_lid_are_the_nominal_figure_at_zero(bumpy, feedback_plan, tmp_path):
    """The bump planned by feedback in the cell of a lid over 40 % of it: the controller in
    the loop and the replay meet the same lid (in the nominal frame) as `evaluate` does, so
    at zero perturbation both give the nominal figure, which the lid lowers."""
    lid, _ = fixture_files(tmp_path, bumpy)
    _, traj = plan_views(bumpy, SPEC, FeedbackPlanner(), "top", fixtures=[lid])
    write_json(traj, tmp_path / "lid.json")
    traj = read_json(tmp_path / "lid.json")
    nominal = evaluate(bumpy, SPEC, traj, points_per_profile=POINTS, ceiling=False)
    free = evaluate(bumpy, SPEC, feedback_plan, points_per_profile=POINTS, ceiling=False)
    assert nominal.in_spec_coverage < free.in_spec_coverage - 0.3
    zero = "place:0mm,0deg;warp:0mm@200mm"
    assert list(_closed(bumpy, traj, zero, trials=1).per_trial) == [nominal.in_spec_coverage]
    assert list(_open(bumpy, traj, zero, trials=1).per_trial) == [nominal.in_spec_coverage]


def test_a_closed_loop_counts_its_steps_before_any_work():
    # A 90 m pass (in range) at the finest spacing an option allows: 90 million steps and
    # three times as many allowed, refused before a trial allocates one; at 0.5 mm it runs.
    traj = recorded_trajectory()
    meta = {k: v for k, v in traj.meta.items() if k != "robot"}
    meta["views"] = [dict(meta["views"][0])]
    meta["views"][0]["swaths"] = [meta["views"][0]["swaths"][0] | {"end_mm": [89680.0, 0, 400]}]
    views = plan_views_of(replace(traj, meta=meta), "plan")
    assert views[0].swaths[0].length_mm == 90_000.0
    spec = meta["context"]["scan_spec"]
    meta["context"] = meta["context"] | {"scan_spec": spec | {"delta_s_opt_mm": 0.001}}
    with pytest.raises(
        TooLarge, match=r"^plan: closed-loop steps of one trial \(passes of 90000 mm"
    ):
        plan_views_of(replace(traj, meta=meta), "plan")


def test_a_robot_fitted_plan_runs_in_closed_loop_within_the_arms_reach(bumpy, tmp_path):
    """The bump fitted to a UR3e that stands far to its side: the arm gives up the passes'
    far ends, so what is left runs along the edge of its reach. On parts lifted and shifted
    by up to 20 mm the controller's corrections, flown as they are, leave that reach; kept
    within it by the arm's inverse kinematics, every scanning pose of every trial is one the
    arm reaches within its limits on one branch per pass, and the loop still covers the
    part."""
    tcp, T_base_part = parse_pose_arg("0,0,90,0,0,0"), parse_pose_arg("0,490,-250,0,0,0")
    _, traj = plan_views(bumpy, SPEC, FeedbackPlanner(), "top", arm=Arm("ur3e", tcp, T_base_part))
    path = tmp_path / "fitted.json"
    write_json(traj, path)
    traj = read_json(path)
    assert sum(traj.meta["robot"]["scanning_poses_given_up"].values()) > 0

    def out_of_reach(flown):
        sc = flown.scanning
        flange = T_base_part @ flown.poses[sc] @ np.linalg.inv(tcp)
        report = check_reach(flange, "ur3e", swath=flown.swath[sc], scanning=sc[sc])
        return len(report.unreachable) + len(report.limit_violations) + len(report.config_flips)

    assert out_of_reach(traj) == 0
    model = Perturbation.parse("place:±20mm")
    tasks = closed_loop_tasks(bumpy, traj, recorded(traj, SPEC), model, 2, 0, POINTS)
    unguarded = [out_of_reach(fly_trial(replace(task, arm=None))) for task in tasks]
    assert max(unguarded) > 50  # the corrections alone leave the arm's reach
    assert [out_of_reach(fly_trial(task)) for task in tasks] == [0, 0]
    nominal = evaluate(bumpy, SPEC, traj, points_per_profile=POINTS).in_spec_coverage
    assert closed_loop_robustness(tasks).worst > 0.8 * nominal


def test_any_controller_flies_one_plans_lines_and_the_ceiling_replans_them(bumpy, feedback_plan):
    """The feedback and geometric plans' lines are one raster: the feedback controller
    flying the geometric plan's lines at no perturbation is the feedback plan's figure, and
    the geometric planner re-planned on them on the (unperturbed) part is the geometric
    plan's; both judged on the geometric plan's samples. On a part lifted 25 mm the ceiling
    follows it where the replay does not. An open-loop planner has no closed loop."""
    _, geometric = plan_views(bumpy, SPEC, GeometricPlanner(), "top")
    context = recorded(geometric, SPEC)
    lines = plan_views_of(geometric, "g")[0].swaths
    assert [sw.start_mm.tolist() for sw in lines] == [
        sw.start_mm.tolist() for sw in plan_views_of(feedback_plan, "f")[0].swaths
    ]
    zero = Perturbation.parse("place:0mm")

    def flown(planner, model, seed=0, knows_part=False):
        tasks = controller_tasks(
            bumpy, geometric, context, planner, model, 1, seed, POINTS, knows_part=knows_part
        )
        return closed_loop_robustness(tasks).mean

    def judged(plan):
        return evaluate(bumpy, SPEC, plan, points_per_profile=POINTS, ceiling=False)

    assert flown(FeedbackPlanner(), zero) == judged(feedback_plan).in_spec_coverage
    ceiling = flown(GeometricPlanner(), zero, knows_part=True)
    assert ceiling == judged(geometric).in_spec_coverage
    lifted = Perturbation.parse("place:15mm,1deg")  # trial 0 of seed 4: lifted 25 mm
    assert flown(GeometricPlanner(), lifted, 4, True) > 0.9 * ceiling
    assert _open(bumpy, geometric, "place:15mm,1deg", trials=1, seed=4).mean < 0.5 * ceiling
    with pytest.raises(ValueError, match="does not act on measured profiles"):
        controller_tasks(bumpy, geometric, context, GeometricPlanner(), zero, 1)
