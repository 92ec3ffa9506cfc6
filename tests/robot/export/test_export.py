"""Every robot-program dialect parsed back and compared with the thinned targets it came from;
flying the read-back program scans the part as the plan does; an unknown format or a bad
option is one clear error."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import rot_err, snake_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_path
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.robot.export import (
    FORMATS,
    ExportOptions,
    export_program,
    parse_program,
    parse_program_details,
)
from scanplan.robot.export.common import plan_motion
from scanplan.world.part import part_from_mesh

TRAJ = snake_trajectory()


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_round_trip(fmt: str) -> None:
    text = export_program(TRAJ, fmt, OPTIONS)
    poses, scanning = parse_program(text, fmt)
    motion = plan_motion(TRAJ, OPTIONS)
    assert motion.n_planned == len(TRAJ) and len(motion.poses) < len(TRAJ) / 4
    # The program holds the thinned targets: planned poses, in the base frame.
    expected = OPTIONS.part_pose @ TRAJ.poses[motion.source]
    assert poses.shape == expected.shape
    assert np.abs(poses[:, :3, 3] - expected[:, :3, 3]).max() < 1e-3  # 1e-6 m
    assert rot_err(poses, expected).max() < 1e-6
    np.testing.assert_array_equal(scanning, TRAJ.scanning[motion.source])

    details = parse_program_details(text, fmt)
    np.testing.assert_allclose(details.speed_mm_s, motion.speed_mm_s, rtol=1e-5)
    if details.blended is not None:
        np.testing.assert_array_equal(details.blended, motion.blend_mm > 0)


def test_bad_options_and_format() -> None:
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(ValueError, match="part pose"):
        ExportOptions(part_pose=skew)
    with pytest.raises(ValueError, match="program name"):
        ExportOptions(program_name="1 bad")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="chord_tol_mm"):
            ExportOptions(chord_tol_mm=bad)
        with pytest.raises(ValueError, match="angle_tol_deg"):
            ExportOptions(angle_tol_deg=bad)
    with pytest.raises(ValueError, match="travel_speed_mm_s"):
        ExportOptions(scan=ScanSpec(travel_speed_mm_s=0))
    with pytest.raises(ValueError, match="unknown export format"):
        export_program(TRAJ, "gcode", OPTIONS)
    with pytest.raises(ValueError, match="no movel"):
        parse_program("def x():\nend\n", "urscript")


# ---- flying the read-back program scans as the plan does ------------------------------------


@pytest.fixture(scope="module")
def wave_plan():
    """A 240 x 120 mm sheet waving ±15 mm along x and ±5 mm along y, planned by the
    geometric planner: pitch and roll vary along the pass. (part, spec, plan, metrics)."""
    x, y = np.linspace(-120, 120, 97), np.linspace(-60, 60, 25)
    X, Y = np.meshgrid(x, y, indexing="ij")
    Z = 15 * np.sin(2 * np.pi * X / 160) + 5 * np.cos(2 * np.pi * Y / 100)
    idx = np.arange(X.size).reshape(X.shape)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    vertices = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    part = part_from_mesh(trimesh.Trimesh(vertices, faces), "wave")
    spec = ScanSpec()
    traj = plan_path(part, spec, make_planner("geometric"), plan_swaths(part, spec.sensor))
    return part, spec, traj, evaluate(part, spec, traj, points_per_profile=256)


def fly(poses: np.ndarray, scanning: np.ndarray, spacing_mm: float, spec: ScanSpec) -> Trajectory:
    """The scanning runs of a program's read-back targets (`T_part_sensor`) flown as the
    controller flies them: linear moves of the program's TCP (the laser line at W_d,
    `spec.T_sensor_line`; position lerp, orientation slerp, one parameter) at a constant TCP
    speed, so a profile every `spacing_mm` (speed / profile rate) of the TCP's path."""
    T_line = spec.T_sensor_line
    tcp = poses @ T_line
    out, swath = [], []
    runs = np.split(np.arange(len(poses)), np.flatnonzero(np.diff(scanning.astype(int))) + 1)
    for k, run in enumerate(r for r in runs if scanning[r[0]]):
        dense = []
        for a, b in zip(run[:-1], run[1:], strict=True):  # every move at 0.02 mm steps or finer
            p_a, p_b = tcp[a, :3, 3], tcp[b, :3, 3]
            u = np.linspace(0.0, 1.0, int(np.linalg.norm(p_b - p_a) / 0.02) + 50)
            r0 = Rotation.from_matrix(tcp[a, :3, :3])
            turn = (r0.inv() * Rotation.from_matrix(tcp[b, :3, :3])).as_rotvec()
            T = np.tile(np.eye(4), (len(u), 1, 1))
            T[:, :3, :3] = (r0 * Rotation.from_rotvec(u[:, None] * turn)).as_matrix()
            T[:, :3, 3] = p_a + u[:, None] * (p_b - p_a)
            dense.append(T)
        path = np.concatenate(dense)
        arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path[:, :3, 3], axis=0), axis=1))]
        at = np.searchsorted(arc, np.arange(0.0, arc[-1] + 1e-9, spacing_mm))
        out.append(path[np.clip(at, 0, len(path) - 1)])
        swath += [k] * len(at)
    flown = np.concatenate(out) @ np.linalg.inv(T_line)
    return Trajectory(flown, swath, np.ones(len(flown), bool))


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_flying_the_program_scans_as_planned(wave_plan, fmt: str) -> None:
    part, spec, traj, planned = wave_plan
    options = ExportOptions(part_pose=OPTIONS.part_pose, tcp=OPTIONS.tcp, scan=spec)
    motion = plan_motion(traj, options)
    assert len(motion.poses) <= len(traj) / 10
    poses, scanning = parse_program(export_program(traj, fmt, options), fmt)
    # Back in the part's frame, flown at the program's constant TCP speed: a profile every
    # scan speed / profile rate along the TCP's path, which the program puts on the line.
    spacing = options.scan_speed / spec.profile_rate_hz
    poses_part = np.linalg.inv(options.part_pose) @ poses
    flown = fly(poses_part, scanning, spacing, spec)
    assert abs(len(flown) - int(traj.scanning.sum())) <= 0.01 * len(flown)
    metrics = evaluate(part, spec, flown, points_per_profile=256)
    assert abs(metrics.in_spec_coverage - planned.in_spec_coverage) <= 0.01


@pytest.mark.parametrize("fmt", ["urscript", "csv"])
def test_constant_tcp_speed_spaces_profiles_on_the_surface(wave_plan, fmt: str) -> None:
    """The sensor pitches along the waving sheet, so its origin, W_d behind the line, travels
    much farther or shorter than the line does; flown at the program's constant speed the
    beam still meets the part about Δs apart, as planned."""
    part, spec, traj, _ = wave_plan
    options = ExportOptions(part_pose=OPTIONS.part_pose, tcp=OPTIONS.tcp, scan=spec)
    poses, scanning = parse_program(export_program(traj, fmt, options), fmt)
    spacing = options.scan_speed / spec.profile_rate_hz
    assert spacing == pytest.approx(spec.delta_s_opt_mm)
    flown = fly(np.linalg.inv(options.part_pose) @ poses, scanning, spacing, spec)
    origin, beam = flown.poses[:, :3, 3], flown.poses[:, :3, 2]
    t, face = part.ray_engine.first_hit(origin, beam)
    hit = origin + np.where(face[:, None] >= 0, t[:, None], np.nan) * beam
    same = flown.swath[1:] == flown.swath[:-1]
    step = np.linalg.norm(np.diff(hit, axis=0), axis=1)[same]
    step = step[np.isfinite(step)]
    assert len(step) > 0.9 * same.sum()
    # The line meets the sheet at about W_d (±Z_r/2), so the spacing stays near Δs ...
    assert np.median(step) == pytest.approx(spec.delta_s_opt_mm, rel=0.05)
    assert np.quantile(step, 0.95) <= 1.3 * spec.delta_s_opt_mm
    # ... while the sensor's origin travels several times farther or shorter per profile.
    origin_step = np.linalg.norm(np.diff(origin, axis=0), axis=1)[same]
    assert np.abs(origin_step / spec.delta_s_opt_mm - 1).max() > 0.5
