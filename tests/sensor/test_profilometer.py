"""The simulator (profilometer.LineProfilometer) against answers geometry gives: plates, tilts,
steps, ranges, noise."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from scanplan.core import quantities
from scanplan.core.noise import NoiseModel
from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.swaths import Swath
from scanplan.sensor import profilometer
from scanplan.sensor.profilometer import LineProfilometer, PointStatus
from scanplan.world.part import part_from_mesh

SPEC = SensorSpec()
QUIET = SPEC.without_noise()
W_D = SPEC.working_distance_mm
# A pass along +X: x_s = +Y (the laser line), y_s = +X (forward), z_s = -Z.
SWATH = Swath(
    0,
    np.array([0.0, 0.0, W_D]),
    np.array([100.0, 0.0, W_D]),
    np.array([1.0, 0, 0]),
    np.array([0, 1.0, 0]),
)


def plate(size=(2000.0, 2000.0), thickness=10.0, tilt_deg=0.0, z_top=0.0) -> trimesh.Trimesh:
    """A plate whose top face passes through (0, 0, z_top), tilted about +Y by tilt_deg (rising
    towards +X for positive tilt)."""
    box = trimesh.creation.box((size[0], size[1], thickness))
    box.apply_translation((0, 0, z_top - thickness / 2))
    rot = trimesh.transformations.rotation_matrix(math.radians(-tilt_deg), [0, 1, 0])
    box.apply_transform(rot)
    return box


def test_flat_plate_at_working_distance():
    part = part_from_mesh(plate())
    prof = LineProfilometer(part, QUIET).measure(SWATH.pose(0, 0, 0))
    assert prof.valid.sum() == SPEC.points_per_profile
    d = quantities.mean_distance(prof.z_sensor, prof.valid)
    assert d == pytest.approx(W_D, abs=SPEC.z_resolution_mm)
    alpha = quantities.signed_alpha(prof.normals_part, prof.valid, prof.T_part_sensor)
    assert alpha == pytest.approx(0.0, abs=1e-9)
    # The line is 2 W_d tan(FOV/2) = 495 mm long, pixel columns evenly spaced in x.
    width = np.nanmax(prof.x_sensor) - np.nanmin(prof.x_sensor)
    assert width == pytest.approx(SPEC.line_width_mm, rel=1e-4)
    assert SPEC.line_width_mm == pytest.approx(495.0, abs=0.5)
    spacing = np.diff(prof.points_part[:, 1])
    assert np.allclose(spacing, spacing[0], rtol=1e-3)


@pytest.mark.parametrize("tilt_deg", [-20.0, 10.0, 20.0])
def test_tilted_plane_gives_alpha_with_the_sign_that_aligns(tilt_deg):
    part = part_from_mesh(plate(tilt_deg=tilt_deg))
    sensor = LineProfilometer(part, QUIET)
    prof = sensor.measure(SWATH.pose(0, 0, 0))
    alpha = quantities.signed_alpha(prof.normals_part, prof.valid, prof.T_part_sensor)
    # A surface rising along u by beta needs the beam pitched by -beta.
    assert math.degrees(alpha) == pytest.approx(-tilt_deg, abs=1e-6)
    per_point = quantities.point_orientation_error(prof.normals_part, prof.T_part_sensor)
    assert np.degrees(per_point[prof.valid]) == pytest.approx(abs(tilt_deg), abs=1e-6)
    # Applying the increment aligns the beam with the normal.
    aligned = sensor.measure(SWATH.pose(0, 0, alpha))
    alpha2 = quantities.signed_alpha(aligned.normals_part, aligned.valid, aligned.T_part_sensor)
    assert alpha2 == pytest.approx(0.0, abs=1e-6)


def test_step_casts_a_camera_shadow_of_the_predicted_width():
    """Approaching a block of height H ahead (camera on +y_s, the side the sensor moves to),
    the floor is hidden from the camera while the block edge is closer than H*b/z."""
    height, edge_x = 50.0, 100.0
    floor = trimesh.creation.box((400, 2000, 10))
    floor.apply_translation((0, 0, -5))
    block = trimesh.creation.box((200, 2000, height))
    block.apply_translation((edge_x + 100, 0, height / 2))
    part = part_from_mesh(trimesh.util.concatenate([floor, block]))
    s = np.arange(0.0, edge_x - 0.01, 0.25)
    poses = SWATH.poses(s, np.zeros_like(s), np.zeros_like(s))
    scan = LineProfilometer(part, QUIET).measure_many(poses)
    centre = scan.status[:, SPEC.points_per_profile // 2]
    shadowed = s[centre == PointStatus.SHADOWED]
    predicted = height * SPEC.baseline_mm / W_D
    assert predicted == pytest.approx(height * math.tan(math.radians(30)), rel=1e-9)
    assert shadowed.min() == pytest.approx(edge_x - predicted, abs=0.5)
    assert shadowed.max() == pytest.approx(edge_x - 0.25, abs=0.5)
    assert (centre[s < edge_x - predicted - 0.5] == PointStatus.VALID).all()
    # With the camera behind, the same approach casts no shadow.
    behind = LineProfilometer(part, replace(QUIET, camera_side=-1)).measure_many(poses)
    assert (behind.status[:, SPEC.points_per_profile // 2] == PointStatus.VALID).all()


def test_a_fixture_stops_the_laser_and_hides_the_camera_s_view():
    """A lid over the line: no point, none of the lid's. A bar ahead of the line (camera on
    +y_s = +x), 60 mm ahead and 100-120 mm up, out of the laser's plane but across the
    camera's sight line (at x = 60 it is 60·400/231 = 104 mm up): every point shadowed,
    and with the camera behind, every point valid."""
    part = part_from_mesh(plate((400.0, 2000.0)))
    lid = trimesh.creation.box((100.0, 2000.0, 10.0))
    lid.apply_translation((0, 0, 20.0))
    bar = trimesh.creation.box((40.0, 2000.0, 20.0))
    bar.apply_translation((60.0, 0, 110.0))
    pose = SWATH.pose(0, 0, 0)
    bare = LineProfilometer(part, QUIET).measure(pose)
    assert bare.valid.all()
    lidded = LineProfilometer(part.among([lid]), QUIET).measure(pose)
    assert (lidded.status == PointStatus.NO_HIT).all() and (lidded.face == -1).all()
    assert np.isnan(lidded.points_part).all()
    barred = LineProfilometer(part.among([bar]), QUIET).measure(pose)
    assert (barred.status == PointStatus.SHADOWED).all()
    assert np.array_equal(barred.true_z_sensor, bare.true_z_sensor)  # the laser reached it
    behind = LineProfilometer(part.among([bar]), replace(QUIET, camera_side=-1)).measure(pose)
    assert behind.valid.all()


@pytest.mark.parametrize("z_top", [-150.0, 150.0])
def test_plate_outside_the_depth_window_returns_nothing(z_top):
    part = part_from_mesh(plate(z_top=z_top))
    prof = LineProfilometer(part, SPEC).measure(SWATH.pose(0, 0, 0))
    assert not prof.valid.any()
    assert (prof.status == PointStatus.OUT_OF_RANGE).all()
    assert np.isnan(prof.z_sensor).all()
    assert np.isnan(quantities.mean_distance(prof.z_sensor, prof.valid))


def test_plate_just_inside_the_window_edge_is_valid():
    part = part_from_mesh(plate(z_top=-120.0))  # depth 520 < 525 at the centre column
    prof = LineProfilometer(part, QUIET).measure(SWATH.pose(0, 0, 0))
    centre = SPEC.points_per_profile // 2
    assert prof.valid[centre]
    assert prof.z_sensor[centre] == pytest.approx(520.0, abs=SPEC.z_resolution_mm)


def test_grazing_incidence_is_cut_off():
    part = part_from_mesh(plate(tilt_deg=85.0, size=(200, 2000)))
    prof = LineProfilometer(part, QUIET).measure(SWATH.pose(0, 0, 0))
    hit = prof.status != PointStatus.NO_HIT
    assert hit.any()
    assert not prof.valid.any()
    assert (prof.status[hit] == PointStatus.GRAZING).any()


def test_inconsistent_winding_gives_the_same_profile():
    mesh = plate(tilt_deg=15.0)
    flipped = mesh.copy()
    flipped.faces = flipped.faces[:, ::-1]
    a = LineProfilometer(part_from_mesh(mesh), QUIET).measure(SWATH.pose(0, 0, 0))
    b = LineProfilometer(part_from_mesh(flipped), QUIET).measure(SWATH.pose(0, 0, 0))
    assert np.array_equal(a.valid, b.valid)
    assert np.allclose(a.normals_part, b.normals_part)


def test_gaussian_noise_matches_the_configured_sigma():
    noise = NoiseModel(sigma0_mm=0.004, speckle_amplitude_mm=0.0)
    spec = replace(SPEC, noise=noise, z_resolution_mm=0.0)
    part = part_from_mesh(plate(z_top=-50.0))  # depth 450 mm
    prof = LineProfilometer(part, spec, seed=1).measure(SWATH.pose(0, 0, 0))
    err = (prof.z_sensor - prof.true_z_sensor)[prof.valid]
    # Off-centre columns meet the plate at the fan angle: sigma0 (z/W_d)^2 / cos(incidence).
    cos_incidence = np.cos(np.arctan(prof.x_sensor[prof.valid] / prof.true_z_sensor[prof.valid]))
    expected = 0.004 * (450 / W_D) ** 2 / cos_incidence
    assert np.std(err / expected) == pytest.approx(1.0, rel=0.05)
    assert abs(np.mean(err / expected)) < 4 / math.sqrt(prof.valid.sum())


def test_noise_grows_with_incidence():
    noise = NoiseModel(sigma0_mm=0.004, speckle_amplitude_mm=0.0)
    spec = replace(SPEC, noise=noise, z_resolution_mm=0.0)
    part = part_from_mesh(plate(tilt_deg=40.0))
    prof = LineProfilometer(part, spec, seed=2).measure(SWATH.pose(0, 0, 0))
    err = (prof.z_sensor - prof.true_z_sensor)[prof.valid]
    z = prof.true_z_sensor[prof.valid]
    normalized = err / (0.004 * (z / W_D) ** 2 / math.cos(math.radians(40.0)))
    assert np.std(normalized) == pytest.approx(1.0, rel=0.06)


def test_speckle_is_a_coherent_function_of_the_surface_point():
    spec = replace(SPEC, noise=NoiseModel(sigma0_mm=0.0), z_resolution_mm=0.0)
    part = part_from_mesh(plate(z_top=0.3))  # off the noise lattice's planes
    sensor = LineProfilometer(part, spec)
    a = sensor.measure(SWATH.pose(0, 0.3, 0))
    # Another pose that lights the same line from a different height sees the same speckle.
    b = sensor.measure(SWATH.pose(0, 20.3, 0))
    ea, eb = a.z_sensor - a.true_z_sensor, b.z_sensor - b.true_z_sensor
    ya, yb = a.points_part[:, 1], b.points_part[:, 1]
    assert np.std(ea) > 0.002
    assert np.interp(ya, yb, eb) == pytest.approx(ea, abs=0.002)
    # Coherent along the line: neighbours 0.12 mm apart correlate (white noise would not),
    # points 5 speckle lengths apart do not.
    assert np.corrcoef(ea[:-1], ea[1:])[0, 1] > 0.7
    assert abs(np.corrcoef(ea[:-20], ea[20:])[0, 1]) < 0.3


def test_quantization_to_the_z_resolution():
    spec = replace(SPEC, noise=NoiseModel(sigma0_mm=0.01, speckle_amplitude_mm=0.0))
    prof = LineProfilometer(part_from_mesh(plate()), spec).measure(SWATH.pose(0, 0, 0))
    steps = prof.z_sensor[prof.valid] / spec.z_resolution_mm
    assert np.allclose(steps, np.round(steps), atol=1e-6)


def test_same_seed_same_profile_and_batch_equals_single():
    part = part_from_mesh(plate(tilt_deg=12.0))
    poses = SWATH.poses(np.linspace(0, 40, 30), np.zeros(30), np.linspace(-0.1, 0.1, 30))
    a = LineProfilometer(part, SPEC, seed=5).measure_many(poses)
    b = LineProfilometer(part, SPEC, seed=5).measure_many(poses)
    c = LineProfilometer(part, SPEC, seed=6).measure_many(poses)
    assert np.array_equal(a.z_sensor, b.z_sensor, equal_nan=True)
    assert not np.array_equal(a.z_sensor, c.z_sensor, equal_nan=True)
    quiet = LineProfilometer(part, QUIET)
    batch = quiet.measure_many(poses)
    for i in (0, 13, 29):
        single = quiet.measure(poses[i])
        assert np.array_equal(single.z_sensor, batch.z_sensor[i], equal_nan=True)
    # A batch large enough to be chunked over threads is still reproducible.
    many = SWATH.poses(np.linspace(0, 40, 120), np.zeros(120), np.zeros(120))
    x = LineProfilometer(part, SPEC, seed=9).measure_many(many)
    y = LineProfilometer(part, SPEC, seed=9, threads=1).measure_many(many)
    assert np.array_equal(x.z_sensor, y.z_sensor, equal_nan=True)


@pytest.mark.parametrize("ahead_rays", [0, profilometer.AHEAD_RAYS])  # one ahead, two
def test_chunks_measured_ahead_are_the_scan_measured_in_turn(ahead_rays, monkeypatch):
    monkeypatch.setattr(profilometer, "AHEAD_RAYS", ahead_rays)
    part = part_from_mesh(plate(tilt_deg=12.0))
    spec = SPEC.with_points(64)
    poses = SWATH.poses(np.linspace(0, 40, 50), np.zeros(50), np.zeros(50))
    turn = LineProfilometer(part, spec, seed=4)
    expected = [turn.measure_many(poses[lo : lo + 8]) for lo in range(0, 50, 8)]
    chunks = list(LineProfilometer(part, spec, seed=4).measure_in_chunks(poses, 8))
    assert [lo for lo, _ in chunks] == list(range(0, 50, 8))
    for (_, got), want in zip(chunks, expected, strict=True):
        assert np.array_equal(got.z_sensor, want.z_sensor, equal_nan=True)
    # A caller that stops after the first chunk is not kept waiting for the rest.
    stream = LineProfilometer(part, spec, seed=4).measure_in_chunks(poses, 8)
    first = next(stream)[1]
    stream.close()
    assert np.array_equal(first.z_sensor, expected[0].z_sensor, equal_nan=True)
