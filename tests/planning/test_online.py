"""A controller run online (scanplan.planning.online), driven by the simulator's profiles as a robot
loop would drive it: it keeps the sensor at its working distance and square to a plate that
is tilted and lifted away from the plan's nominal plate, which the plan replayed does not."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from helpers import WD, plate_swath
from scanplan.core.quantities import ScanSpec, point_orientation_error
from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.online import OnlinePass, estimate_normals, pass_state
from scanplan.planning.planners.feedback import FeedbackController
from scanplan.rl.planner import RLPlanner
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import part_from_mesh

SPEC = ScanSpec(SensorSpec().with_points(512))  # noise on: a sensor's profile
TILT_DEG, LIFT_MM = 4.0, 15.0
START_MM = 420.0  # along the pass from its start at x = -320: x = 100 mm


@pytest.fixture(scope="module")
def tilted_lifted():
    """A 1000 x 300 plate tilted 4° about y (rising along the pass +x) and lifted 15 mm: the
    plan was made 400 mm above a flat plate at z = 0."""
    box = trimesh.creation.box((1000.0, 300.0, 10.0))
    box.apply_translation((0, 0, -5.0))
    box.apply_transform(trimesh.transformations.rotation_matrix(math.radians(-TILT_DEG), [0, 1, 0]))
    box.apply_translation((0, 0, LIFT_MM))
    return part_from_mesh(box, "tilted plate")


def _drive(part, controller, steps=600, roll=False):
    """The loop a robot runs: servo to the pose, read the profile, ask for the next pose."""
    swath = plate_swath()
    sim = LineProfilometer(part, SPEC.sensor, seed=1)
    loop = OnlinePass(swath, SPEC, controller, roll=roll)
    pose = swath.pose(START_MM, 0.0, 0.0)
    depth, pitch = [], []
    for _ in range(steps):
        profile = sim.measure(pose)
        depth.append(np.nanmean(np.where(profile.valid, profile.z_sensor, np.nan)))
        pitch.append(pass_state(swath, pose)[2])
        pose = loop.step(pose, profile.x_sensor, profile.z_sensor)
    return np.array(depth), np.degrees(pitch), loop


def test_the_feedback_controller_online_follows_a_tilted_lifted_plate(tilted_lifted):
    depth, pitch, loop = _drive(tilted_lifted, FeedbackController())
    # The pass starts 22 mm short of W_d (lift + tilt at x = 100 mm): beyond the tolerance.
    assert WD - depth[0] > SPEC.tolerance_mm
    settled = slice(150, None)
    assert np.abs(depth[settled] - WD).max() < 1.0
    # Square to the rising plate: the beam leans forward (θ < 0 leans it towards +u).
    assert np.abs(pitch[settled] + TILT_DEG).max() < 0.5
    # Each step advanced about Δs_opt along the surface.
    assert loop.dynamics.delta_s_mm == pytest.approx(SPEC.delta_s_opt_mm, rel=0.2)
    # The nominal pose replayed: the depth error only grows along the rising plate.
    sim = LineProfilometer(tilted_lifted, SPEC.sensor, seed=1)
    replayed = sim.measure(plate_swath().pose(START_MM + 0.5 * len(depth), 0.0, 0.0))
    assert WD - np.nanmean(np.where(replayed.valid, replayed.z_sensor, np.nan)) > 30.0


def test_the_shipped_policy_online_follows_it_too(tilted_lifted):
    depth, pitch, _ = _drive(tilted_lifted, RLPlanner.default().controller())
    settled = slice(200, None)
    assert np.abs(depth[settled] - WD).max() < 1.0
    assert np.abs(pitch[settled] + TILT_DEG).max() < 0.5


def test_normals_estimated_from_two_profiles_are_the_surface_normals(tilted_lifted):
    swath = plate_swath()
    sim = LineProfilometer(tilted_lifted, SPEC.sensor, seed=1)
    a, b = (sim.measure(swath.pose(s, 0.0, math.radians(2.0))) for s in (200.0, 200.5))
    normals = estimate_normals(b.points_part, b.valid, b.T_part_sensor, a.points_part, a.valid)
    known = np.linalg.norm(normals, axis=1) > 0
    assert known.sum() > 0.9 * b.valid.sum()
    mean = normals[known].sum(axis=0)
    mean /= np.linalg.norm(mean)
    truth = b.normals_part[b.valid].mean(axis=0)
    truth /= np.linalg.norm(truth)
    assert math.degrees(math.acos(min(1.0, mean @ truth))) < 0.2
    # Without the previous profile only the slope across the line is known: α reads as 0.
    alone = estimate_normals(b.points_part, b.valid, b.T_part_sensor)
    error = point_orientation_error(alone[alone.any(axis=1)], b.T_part_sensor)
    assert np.allclose(error, 0.0, atol=0.05)


def test_pass_state_inverts_the_pass_pose_with_and_without_roll():
    swath = plate_swath()
    state = np.array([120.0, -7.5, math.radians(6.0)])
    assert np.allclose(pass_state(swath, swath.pose(*state)), state)
    rolled = np.array([80.0, 3.0, math.radians(-4.0), math.radians(9.0), 12.0])
    assert np.allclose(pass_state(swath, swath.pose(*rolled), roll=True), rolled)


def test_a_profile_of_mismatched_columns_is_refused():
    loop = OnlinePass(plate_swath(), SPEC, FeedbackController())
    with pytest.raises(ValueError, match="3 lateral positions for 2 depths"):
        loop.step(np.eye(4), np.zeros(3), np.ones(2))
