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
from scanplan.export import (
    FORMATS,
    ExportOptions,
    export_program,
    parse_program,
    parse_program_details,
)
from scanplan.export.common import plan_motion
from scanplan.metrics import evaluate
from scanplan.part import part_from_mesh
from scanplan.pipeline import plan_path
from scanplan.planners import make_planner
from scanplan.quantities import ScanSpec
from scanplan.swaths import plan_swaths
from scanplan.trajectory import Trajectory

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


def fly(poses: np.ndarray, scanning: np.ndarray, spacing_mm: float, wd_mm: float) -> Trajectory:
    """The scanning runs of a program's targets flown by linear moves (position lerp,
    orientation slerp, one parameter), a profile every `spacing_mm` of the path of the line
    (the beam's point at the working distance `wd_mm`), as the plan spaces its profiles."""
    out, swath = [], []
    runs = np.split(np.arange(len(poses)), np.flatnonzero(np.diff(scanning.astype(int))) + 1)
    for k, run in enumerate(r for r in runs if scanning[r[0]]):
        dense = []
        for a, b in zip(run[:-1], run[1:], strict=True):  # every move at 0.02 mm steps or finer
            line_a, line_b = (poses[i, :3, 3] + wd_mm * poses[i, :3, 2] for i in (a, b))
            u = np.linspace(0.0, 1.0, int(np.linalg.norm(line_b - line_a) / 0.02) + 50)
            r0 = Rotation.from_matrix(poses[a, :3, :3])
            turn = (r0.inv() * Rotation.from_matrix(poses[b, :3, :3])).as_rotvec()
            T = np.tile(np.eye(4), (len(u), 1, 1))
            T[:, :3, :3] = (r0 * Rotation.from_rotvec(u[:, None] * turn)).as_matrix()
            T[:, :3, 3] = poses[a, :3, 3] + u[:, None] * (poses[b, :3, 3] - poses[a, :3, 3])
            dense.append(T)
        path = np.concatenate(dense)
        line = path[:, :3, 3] + wd_mm * path[:, :3, 2]
        arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))]
        at = np.searchsorted(arc, np.arange(0.0, arc[-1] + 1e-9, spacing_mm))
        out.append(path[np.clip(at, 0, len(path) - 1)])
        swath += [k] * len(at)
    flown = np.concatenate(out)
    return Trajectory(flown, swath, np.ones(len(flown), bool))


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_flying_the_program_scans_as_planned(wave_plan, fmt: str) -> None:
    part, spec, traj, planned = wave_plan
    options = ExportOptions(part_pose=OPTIONS.part_pose, tcp=OPTIONS.tcp, scan=spec)
    motion = plan_motion(traj, options)
    assert len(motion.poses) <= len(traj) / 10
    poses, scanning = parse_program(export_program(traj, fmt, options), fmt)
    # Back in the part's frame, a profile every scan speed / profile rate along the line.
    spacing = options.scan_speed / spec.profile_rate_hz
    poses_part = np.linalg.inv(options.part_pose) @ poses
    flown = fly(poses_part, scanning, spacing, spec.working_distance_mm)
    assert abs(len(flown) - int(traj.scanning.sum())) <= 0.01 * len(flown)
    metrics = evaluate(part, spec, flown, points_per_profile=256)
    assert abs(metrics.in_spec_coverage - planned.in_spec_coverage) <= 0.01
