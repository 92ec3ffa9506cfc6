"""Fixed and geometric planners on analytic parts and on the built-in door (SPEC §4); with
roll, the geometric and feedback planners put a cross slope in spec."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from scanplan.core.quantities import ScanSpec, StepLimits
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_path
from scanplan.planning.planners.feedback import FeedbackPlanner
from scanplan.planning.planners.fixed import FixedPlanner
from scanplan.planning.planners.geometric import GeometricPlanner
from scanplan.planning.shaping import CentredLookahead
from scanplan.planning.step_model import steps_between
from scanplan.planning.swaths import plan_swaths
from scanplan.world.part import part_from_mesh

SENSOR = SensorSpec()
SPEC = ScanSpec(SENSOR)
FAN = 256  # sub-sampled evaluation fan: the same answers, 16x faster


def box(length, width, height=10.0, tilt_deg=0.0, offset=(0.0, 0.0, 0.0)):
    mesh = trimesh.creation.box((length, width, height))
    # Tilt about the lateral axis (y) so a pass along x climbs it.
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(tilt_deg), [0, 1, 0]))
    mesh.apply_translation(offset)
    return mesh


def run(part, planner, direction="auto"):
    traj = plan_path(part, SPEC, planner, plan_swaths(part, SENSOR, direction))
    return traj, evaluate(part, SPEC, traj, points_per_profile=FAN)


@pytest.mark.parametrize("planner", [FixedPlanner(), GeometricPlanner()], ids=lambda p: p.name)
def test_flat_plate_both_planners_measure_zero_error_full_coverage(planner):
    part = part_from_mesh(box(600.0, 300.0, offset=(100.0, 50.0, 20.0)), "plate")
    _, m = run(part, planner)
    assert m.distance_error_mean_abs_mm < 0.02  # noise only
    assert m.profile_distance_error_mean_abs_mm < 0.01
    assert m.orientation_error_mean_deg < 0.01
    assert m.coverage_fraction > 0.99
    assert m.spacing_mean_mm == pytest.approx(0.5, abs=0.005)
    assert m.backward_steps == 0


def test_tilted_plate_fixed_shows_the_tilt_geometric_aligns(tilted_plate):
    part = tilted_plate
    _, fixed = run(part, FixedPlanner())
    _, geo = run(part, GeometricPlanner())
    assert fixed.orientation_error_mean_deg == pytest.approx(20.0, abs=0.5)
    assert geo.orientation_error_mean_deg < 1.0
    assert geo.distance_error_mean_abs_mm < 0.1 * fixed.distance_error_mean_abs_mm
    assert geo.spacing_mean_mm == pytest.approx(0.5, abs=0.02)
    assert geo.backward_steps == 0


def test_geometric_respects_the_step_limits_and_anticipates_a_step(stepped_plate):
    part = stepped_plate
    (swath,) = plan_swaths(part, SENSOR, "x")
    limits = StepLimits()
    traj = GeometricPlanner(limits=limits).plan(part, swath, SPEC)
    shf = np.array([swath.to_swath_frame(p) for p in traj.poses])
    actions = steps_between(shf[:, 0], shf[:, 1], shf[:, 2])
    bound = [limits.dy_max_mm, limits.dz_max_mm, limits.dtheta_max_rad]
    assert np.all(np.abs(actions) <= np.array(bound) + 1e-9)
    # The rise starts before the footprint reaches the step (x = 0): look-ahead, no lag.
    height = traj.poses[:, 2, 3]
    footprint_x = traj.poses[:, 0, 3] + 400.0 * traj.poses[:, 0, 2]
    before = footprint_x < -1.0
    assert height[before].max() > height[0] + 5.0
    m = evaluate(part, SPEC, traj, points_per_profile=FAN)
    f = evaluate(part, SPEC, FixedPlanner().plan(part, swath, SPEC), points_per_profile=FAN)
    assert m.profile_distance_error_mean_abs_mm < 0.25 * f.profile_distance_error_mean_abs_mm
    assert m.backward_steps == 0


def test_planner_takes_its_cost_as_a_strategy(door):
    calls = []

    def cost(d, alpha, ds, spec):
        calls.append(len(d))
        return -len(calls)  # the last candidate costed wins

    swath = plan_swaths(door, SENSOR)[0]
    planner = GeometricPlanner(cost=cost, refinements=0)
    traj = planner.plan(door, swath, SPEC)
    assert len(calls) == 3  # one per look-ahead candidate: over a curved door they all differ
    last = replace(planner, lookaheads=planner.lookaheads[-1:]).plan(door, swath, SPEC)
    np.testing.assert_array_equal(traj.poses, last.poses)


def test_identical_stations_are_measured_and_costed_once(door):
    calls = []

    def cost(d, alpha, ds, spec):
        calls.append(len(d))
        return 0.0

    swath = plan_swaths(door, SENSOR)[0]
    one = GeometricPlanner(cost=cost, lookaheads=(CentredLookahead(15.0),), refinements=2)
    one.plan(door, swath, SPEC)
    alone = len(calls)
    assert alone == 3  # each refinement moves the stations over a curved door
    # A second, identical look-ahead gives the same stations at every step: nothing new.
    twice = replace(one, lookaheads=(CentredLookahead(15.0), CentredLookahead(15.0)))
    twice.plan(door, swath, SPEC)
    assert len(calls) == 2 * alone


def test_pass_that_sees_nothing_is_a_clear_error():
    part = part_from_mesh(box(300.0, 100.0), "plate")
    (swath,) = plan_swaths(part, SENSOR)
    far = type(swath)(
        0, swath.start_mm + [0, 5000, 0], swath.end_mm + [0, 5000, 0], swath.u, swath.v
    )
    for planner in (FixedPlanner(), GeometricPlanner()):
        with pytest.raises(ValueError, match="outside the sensor's reach"):
            planner.plan(part, far, SPEC)


@pytest.mark.slow
def test_door_geometric_beats_fixed(door_plans):
    """Passes across the door's tumblehome (direction y) so the curvature lies along the
    pass, where pitch and height can follow it. Along the long axis the tumblehome lies
    across the laser line, which no planner can correct with roll fixed. Direction y is the
    door's auto direction (test_swaths), so these are the door's default plans."""
    assert all(abs(swath.u[1]) == pytest.approx(1.0) for swath in door_plans.swaths)
    fixed = door_plans.metrics("fixed")
    traj = door_plans.plan("geometric", roll=False)
    geo = door_plans.metrics("geometric", roll=False)
    assert geo.distance_error_mean_abs_mm <= 0.25 * fixed.distance_error_mean_abs_mm
    assert geo.orientation_error_mean_deg <= 0.5 * fixed.orientation_error_mean_deg
    assert fixed.coverage_fraction >= 0.9 and geo.coverage_fraction >= 0.9
    assert fixed.backward_steps == 0 and geo.backward_steps == 0
    assert geo.reward_mean > fixed.reward_mean
    assert traj.plan_time_s < 30.0


@pytest.mark.slow
def test_door_default_direction_geometric_holds_the_working_distance(door_plans):
    fixed = door_plans.metrics("fixed")
    geo = door_plans.metrics("geometric", roll=False)
    assert geo.profile_distance_error_mean_abs_mm <= 0.25 * fixed.profile_distance_error_mean_abs_mm
    assert geo.coverage_fraction >= 0.9 and fixed.coverage_fraction >= 0.9
    assert geo.backward_steps == 0
    assert geo.reward_mean > fixed.reward_mean


def test_cross_slope_pitch_only_is_out_of_spec_roll_puts_it_in_spec(cross_slope_plate):
    part = cross_slope_plate
    swaths = plan_swaths(part, SPEC.sensor, "x")
    pitch_only = plan_path(part, SPEC, GeometricPlanner(), swaths)
    rolled = plan_path(part, SPEC, GeometricPlanner.with_roll(), swaths)
    feedback = plan_path(part, SPEC, FeedbackPlanner(roll=True), swaths)
    m0 = evaluate(part, SPEC, pitch_only, points_per_profile=256)
    m1 = evaluate(part, SPEC, rolled, points_per_profile=256)
    m2 = evaluate(part, SPEC, feedback, points_per_profile=256)
    assert m0.in_spec_coverage < 0.02  # every point at 20° > 15°
    assert m1.in_spec_coverage >= 0.95
    assert m2.in_spec_coverage >= 0.9  # the feedback controller rolls into it from 15°
    assert m1.orientation_error_mean_deg < 1.0
