"""Thinning the planned poses to few linear-move targets (export.thinning, plan_motion): the
path flown through the targets stays within the chord and angle tolerances of every planned
pose; blends cut it by no more than the chord tolerance and never overlap."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import FAST, snake_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.robot.export import ExportOptions
from scanplan.robot.export.common import MOVE_BLEND_MM, MOVE_CUT_SHARE, plan_motion
from scanplan.robot.export.joint_moves import joint_move_targets
from scanplan.robot.export.thinning import interp_params, thin_run

TRAJ = snake_trajectory()


def flown_error(planned: np.ndarray, kept: np.ndarray, chord_mm: float, angle_rad: float):
    """(n,) for each planned pose: the least, over a dense sampling of the linear moves
    between the kept targets (position lerp, orientation slerp, one parameter), of the larger
    of its position and angle errors, each over its tolerance; <= 1 means within both. The
    samples lie 1/40 of a tolerance apart, so sampling adds at most 0.025 to the answer."""
    worst = np.zeros(len(planned))
    quat = Rotation.from_matrix(planned[:, :3, :3]).as_quat()
    for a, b in zip(kept[:-1], kept[1:], strict=True):
        p0, p1 = planned[a, :3, 3], planned[b, :3, 3]
        r0 = Rotation.from_matrix(planned[a, :3, :3])
        turn = (r0.inv() * Rotation.from_matrix(planned[b, :3, :3])).as_rotvec()
        n = np.linalg.norm(p1 - p0) / chord_mm + np.linalg.norm(turn) / angle_rad
        u = np.linspace(0.0, 1.0, int(np.clip(40 * n, 100, 50_000)))
        flown_p = p0 + u[:, None] * (p1 - p0)
        flown_q = (r0 * Rotation.from_rotvec(u[:, None] * turn)).as_quat()
        k = np.arange(a, b + 1)
        d = np.linalg.norm(flown_p[None] - planned[k, None, :3, 3], axis=2) / chord_mm
        ang = 2 * np.arccos(np.clip(np.abs(quat[k] @ flown_q.T), 0.0, 1.0)) / angle_rad
        worst[k] = np.maximum(d, ang).min(axis=1)
    return worst


def test_straight_constant_run_keeps_its_ends() -> None:
    poses = np.tile(np.eye(4), (50, 1, 1))
    poses[:, 0, 3] = np.linspace(0.0, 100.0, 50) ** 1.5 / 10  # uneven spacing, one line
    np.testing.assert_array_equal(thin_run(poses, 0.1, np.radians(0.1)), [0, 49])
    # A turn on the spot (no travel) is interpolated by index.
    spin = np.tile(np.eye(4), (5, 1, 1))
    yaw = np.linspace(0, 40, 5)[:, None]
    spin[:, :3, :3] = Rotation.from_euler("z", yaw, degrees=True).as_matrix()
    np.testing.assert_array_equal(thin_run(spin, 0.1, np.radians(0.1)), [0, 4])
    np.testing.assert_allclose(interp_params(spin[:, :3, 3]), np.linspace(0, 1, 5))


def test_snake_thinned_within_tolerances() -> None:
    m = plan_motion(TRAJ, OPTIONS)
    # Defaults: shares of the in-spec tolerances, 0.5 mm and 0.5° for the default sensor.
    assert OPTIONS.chord_tol == pytest.approx(ScanSpec().tolerance_mm / 25) == 0.5
    assert np.degrees(OPTIONS.angle_tol_rad) == pytest.approx(0.5)
    assert m.n_planned == len(TRAJ) and len(m.poses) < len(TRAJ) / 4
    # Targets are the TCP, the laser line at W_d; thinned on the line's path.
    tcp = TRAJ.poses @ OPTIONS.scan.T_sensor_line
    np.testing.assert_allclose(m.poses_part, tcp[m.source], atol=1e-9)
    # Pass starts and ends are kept, so every pass still begins and ends where planned.
    starts = np.flatnonzero(np.r_[True, TRAJ.scanning[1:] & ~TRAJ.scanning[:-1]] & TRAJ.scanning)
    assert set(starts) <= set(m.source[m.pass_start])
    worst = flown_error(tcp, m.source, OPTIONS.chord_tol, OPTIONS.angle_tol_rad)
    assert worst.max() <= 1.03
    # Tighter tolerances keep more targets, and still hold.
    tight = ExportOptions(chord_tol_mm=0.05, angle_tol_deg=0.05)
    mt = plan_motion(TRAJ, tight)
    assert len(mt.poses) > len(m.poses)
    assert flown_error(tcp, mt.source, 0.05, np.radians(0.05)).max() <= 1.03


@settings(FAST, max_examples=40)
@given(
    seed=st.integers(0, 2**31 - 1),
    chord=st.floats(0.05, 2.0),
    angle_deg=st.floats(0.05, 3.0),
)
def test_any_wavy_run_thinned_within_tolerances(seed: int, chord: float, angle_deg: float) -> None:
    rng = np.random.default_rng(seed)
    n = 120
    s = np.cumsum(rng.uniform(0.2, 0.6, n))
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.column_stack(
        [s, rng.normal(0, 0.3) * np.sin(s / 7), 3 * np.sin(s / rng.uniform(3, 20))]
    )
    pitch = 0.4 * np.cos(s / rng.uniform(3, 20)) + rng.normal(0, 0.002, n)
    poses[:, :3, :3] = Rotation.from_euler("yx", np.column_stack([pitch, pitch / 3])).as_matrix()
    kept = thin_run(poses, chord, np.radians(angle_deg))
    assert kept[0] == 0 and kept[-1] == n - 1 and np.all(np.diff(kept) > 0)
    assert flown_error(poses, kept, chord, np.radians(angle_deg)).max() <= 1.03


def test_blends_cut_the_path_by_at_most_the_chord_tolerance() -> None:
    """In a pass by the chord tolerance; in a move between passes by a share of the
    clearance the move was planned with."""
    wide = ExportOptions(blend_mm=50.0, chord_tol_mm=0.3, angle_tol_deg=1.0)
    m = plan_motion(TRAJ, wide)
    p = m.poses[:, :3, 3]
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    inner = np.flatnonzero(m.blend_mm > 0)
    assert len(inner) > 0
    ends = m.pass_start | m.pass_end
    ends[[0, -1]] = True
    assert np.all(m.blend_mm[ends] == 0)
    assert wide.move_cut_mm == pytest.approx(20.0 * MOVE_CUT_SHARE)
    for i in inner:
        cut = 0.3 if m.scanning[i] else wide.move_cut_mm
        r = m.blend_mm[i]
        # No overlap with the neighbours' blends.
        assert r <= 0.5 * min(seg[i - 1], seg[i]) + 1e-9
        # A blend from r before the corner to r after it cuts the corner by r·sin(θ/2).
        a, b = p[i] - p[i - 1], p[i + 1] - p[i]
        cos_turn = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
        assert r * np.sqrt((1 - min(cos_turn, 1.0)) / 2) <= cut + 1e-9
    # A straight scanning run is blended up to blend_mm, the neighbours permitting.
    line = np.tile(np.eye(4), (5, 1, 1))
    line[:, 0, 3] = [0, 100, 200, 300, 400]
    line[1:4, 1, 3] = [2.0, 4.0, 2.0]  # a corner, kept; the poses on the two moves are not
    corner = plan_motion(Trajectory(line, [0] * 5, [True] * 5), ExportOptions(blend_mm=500.0))
    np.testing.assert_array_equal(corner.source, [0, 2, 4])
    # 0.5 mm (the chord tolerance) over sin(θ/2), below half the 200 mm moves.
    np.testing.assert_allclose(corner.blend_mm, [0, 0.5 / np.sin(np.arctan(4 / 200)), 0])


def _lifted_move() -> Trajectory:
    """Pass 0 along +x, a move up 100, over 300 (with a 90° corner each end) and down 100,
    pass 1 back: the move's via points are corners no thinning drops."""
    xyz = [[0, 0, 0], [100, 0, 0], [200, 0, 0]]
    xyz += [[200, 0, 100], [200, 150, 100], [200, 300, 100]]
    xyz += [[200, 300, 0], [100, 300, 0], [0, 300, 0]]
    poses = np.tile(np.eye(4), (len(xyz), 1, 1))
    poses[:, :3, 3] = xyz
    scanning = [True] * 3 + [False] * 3 + [True] * 3
    return Trajectory(poses, [0, 0, 0, 1, 1, 1, 1, 1, 1], scanning)


def test_a_move_between_passes_is_blended_but_not_into_a_joint_move() -> None:
    traj = _lifted_move()
    options = ExportOptions(scan=ScanSpec(clearance_mm=20.0))
    m = plan_motion(traj, options)
    np.testing.assert_array_equal(m.source, [0, 2, 3, 5, 6, 8])
    # The two 90° corners of the move: cut by the clearance's share, r·sin 45° = 5 mm.
    r = 5.0 / np.sin(np.pi / 4)
    np.testing.assert_allclose(m.blend_mm, [0, 0, r, r, 0, 0])
    # Capped by the largest move blend asked for, and by default at MOVE_BLEND_MM.
    small = plan_motion(traj, ExportOptions(scan=options.scan, move_blend_mm=3.0))
    np.testing.assert_allclose(small.blend_mm, [0, 0, 3, 3, 0, 0])
    assert options.move_blend_mm == MOVE_BLEND_MM > r
    # With the arm's joints the program enters pass 1 by a joint move: it starts standing.
    joints = np.zeros((len(traj), 6))
    jm = plan_motion(traj, ExportOptions(scan=options.scan, joints_rad=joints))
    np.testing.assert_allclose(jm.blend_mm, [0, 0, r, 0, 0, 0])
    # Where the joints are unknown there is no joint move, and the blend stays.
    joints[6] = np.nan
    np.testing.assert_allclose(
        plan_motion(traj, ExportOptions(scan=options.scan, joints_rad=joints)).blend_mm,
        [0, 0, r, r, 0, 0],
    )
    # No clearance, no room to cut a corner: exact stops.
    tight = plan_motion(traj, ExportOptions(scan=ScanSpec(clearance_mm=0.0)))
    np.testing.assert_array_equal(tight.blend_mm, 0.0)


def test_a_pass_the_plan_enters_at_the_top_of_its_move_is_entered_there() -> None:
    # The fit recorded pass 1's entry at the top of the move into it (pose 4), where the arm
    # reconfigures clear of the part: a target, where the joint move ends standing.
    traj = _lifted_move()
    record = {"pass_entry_joints_deg": {"0": [0.0] * 6, "4": [0.0] * 6}}
    traj = replace(traj, meta={"robot": record})
    options = ExportOptions(scan=ScanSpec(clearance_mm=20.0), joints_rad=np.zeros((9, 6)))
    m = plan_motion(traj, options)
    assert m.entry is not None
    np.testing.assert_array_equal(m.source, [0, 2, 3, 4, 5, 6, 8])
    np.testing.assert_array_equal(m.source[m.entry], [0, 4])
    r = 5.0 / np.sin(np.pi / 4)
    np.testing.assert_allclose(m.blend_mm, [0, 0, 0, 0, r, 0, 0])
    assert sorted(joint_move_targets(m, options)) == [0, 3]
