"""The cycle-time model: trapezoids checked against their closed forms, the structure of a
trajectory (passes, moves, joint moves) against hand-computed sums."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import plate_file, run_cli
from scanplan.core.cycle import NOMINAL, MotionLimits, cycle_time, trapezoid_time_s, view_seconds
from scanplan.core.plan_file import write_csv
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory, pass_entries
from scanplan.planning.swaths import Swath
from scanplan.robot import motion_limits

# Limits whose rotation and joints never bind unless a test says so.
FAST = replace(NOMINAL, name="fast", angular_speed_deg_s=1e6, angular_accel_deg_s2=1e9)


def poses_at(xyz: np.ndarray, rotvec_deg: np.ndarray | None = None) -> np.ndarray:
    xyz = np.asarray(xyz, dtype=np.float64)
    T = np.tile(np.eye(4), (len(xyz), 1, 1))
    T[:, :3, 3] = xyz
    if rotvec_deg is not None:
        T[:, :3, :3] = Rotation.from_rotvec(rotvec_deg, degrees=True).as_matrix()
    return T


def one_pass(length_mm: float, stations: int = 11) -> Trajectory:
    x = np.linspace(0.0, length_mm, stations)
    xyz = np.c_[x, np.zeros_like(x), np.full_like(x, 400.0)]
    return Trajectory(poses_at(xyz), np.zeros(stations, int), np.ones(stations, bool))


def spec_at(speed_mm_s: float, travel_mm_s: float = 250.0) -> ScanSpec:
    """A spec whose scan speed (profile rate x spacing) is `speed_mm_s`."""
    return ScanSpec(profile_rate_hz=speed_mm_s / 0.5, travel_speed_mm_s=travel_mm_s)


@pytest.mark.parametrize(
    ("length", "v", "a"),
    [(100.0, 100.0, 1000.0), (10.0, 100.0, 1000.0), (5.0, 100.0, 100.0), (800.0, 50.0, 250.0)],
)
def test_straight_pass_is_the_closed_form_trapezoid(length, v, a) -> None:
    limits = replace(FAST, accel_mm_s2=a)
    ct = cycle_time(one_pass(length), spec_at(v), limits)
    expected = length / v + v / a if length >= v * v / a else 2.0 * math.sqrt(length / a)
    assert ct.total_s == pytest.approx(expected, rel=1e-12)
    assert ct.scanning_s == ct.total_s and ct.moving_s == 0.0
    assert ct.runs == ct.swaths == 1 and len(ct.move_s) == 0


def test_a_pitching_pass_is_timed_on_the_line_the_program_flies() -> None:
    """The line (W_d along the beam) sweeps 100 mm of a flat sheet while the sensor pitches
    ±30°, so its origin travels ~4x farther: timed on the line, the program's TCP."""
    spec = spec_at(100.0)
    wd = spec.working_distance_mm
    x = np.linspace(0.0, 100.0, 201)
    pitch = np.radians(30.0) * np.sin(2 * np.pi * x / 100.0)
    T = np.tile(np.eye(4), (len(x), 1, 1))
    T[:, :3, :3] = Rotation.from_euler("y", pitch[:, None]).as_matrix() @ np.diag([1.0, -1.0, -1.0])
    T[:, :3, 3] = np.c_[x, np.zeros_like(x), np.zeros_like(x)] - wd * T[:, :3, 2]
    traj = Trajectory(T, np.zeros(len(x), int), np.ones(len(x), bool))
    origin_mm = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1).sum()
    assert origin_mm > 3 * 100.0
    ct = cycle_time(traj, spec, FAST)
    assert ct.scanning_s == pytest.approx(100.0 / 100.0 + 100.0 / FAST.accel_mm_s2, rel=1e-9)


def test_trapezoid_is_continuous_where_cruise_is_first_reached() -> None:
    v, a = 100.0, 1000.0
    edge = v * v / a
    below, above = trapezoid_time_s([edge * (1 - 1e-9), edge], v, a)
    assert below == pytest.approx(above) == pytest.approx(2 * v / a)
    assert trapezoid_time_s(0.0, v, a) == 0.0


def test_longer_or_faster_pass() -> None:
    base = cycle_time(one_pass(300.0), spec_at(100.0), FAST).total_s
    assert cycle_time(one_pass(400.0), spec_at(100.0), FAST).total_s > base
    # A slower scan speed takes longer; the arm's Cartesian limit caps a faster one.
    assert cycle_time(one_pass(300.0), spec_at(50.0), FAST).total_s > base
    capped = cycle_time(one_pass(300.0), spec_at(5000.0), FAST)
    assert capped.scan_speed_mm_s == FAST.speed_mm_s


def two_passes_and_a_move() -> Trajectory:
    """Pass 0 along +x (200 mm), a 3-segment move (up 100, over 300, down 100), pass 1 back."""
    xyz = [[0, 0, 0], [100, 0, 0], [200, 0, 0]]  # pass 0
    xyz += [[200, 0, 100], [200, 300, 100]]  # the move's via points
    xyz += [[200, 300, 0], [100, 300, 0], [0, 300, 0]]  # pass 1
    swath = [0, 0, 0, 1, 1, 1, 1, 1]
    scanning = [True, True, True, False, False, True, True, True]
    return Trajectory(poses_at(np.array(xyz, float)), swath, scanning)


def test_passes_and_moves_sum_their_trapezoids() -> None:
    spec = spec_at(100.0, travel_mm_s=250.0)
    ct = cycle_time(two_passes_and_a_move(), spec, FAST)
    a = FAST.accel_mm_s2
    per_pass = 200.0 / 100.0 + 100.0 / a
    np.testing.assert_allclose(ct.pass_s, [per_pass, per_pass])
    move = sum(d / 250.0 + 250.0 / a for d in (100.0, 300.0, 100.0))
    np.testing.assert_allclose(ct.move_s, [move])
    assert ct.total_s == pytest.approx(2 * per_pass + move)
    assert "cycle time" in ct.line() and "in 2 passes" in ct.line() and "fast limits" in ct.line()


def test_travel_speed_is_capped_by_the_arm() -> None:
    slow_arm = replace(FAST, name="slow", speed_mm_s=120.0)
    ct = cycle_time(two_passes_and_a_move(), spec_at(100.0, travel_mm_s=250.0), slow_arm)
    assert ct.travel_speed_mm_s == 120.0
    a = slow_arm.accel_mm_s2
    assert ct.moving_s == pytest.approx(sum(d / 120.0 + 120.0 / a for d in (100, 300, 100)))


def test_a_move_that_turns_is_timed_by_its_rotation() -> None:
    """A 10 mm move that turns the sensor 90° at 30°/s takes the rotation's trapezoid."""
    xyz = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0]], float)
    rot = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 90], [0, 0, 90]], float)
    traj = Trajectory(poses_at(xyz, rot), [0, 0, 1, 1], [True, True, True, True])
    limits = replace(FAST, angular_speed_deg_s=30.0, angular_accel_deg_s2=60.0)
    ct = cycle_time(traj, spec_at(100.0), limits)
    assert ct.move_s[0] == pytest.approx(90.0 / 30.0 + 30.0 / 60.0)
    # The same move without the turn is the short translation's triangle.
    flat = cycle_time(Trajectory(poses_at(xyz), [0, 0, 1, 1], [True] * 4), spec_at(100.0), limits)
    assert flat.move_s[0] == pytest.approx(2.0 * math.sqrt(10.0 / limits.accel_mm_s2))


# Joint 2 turns at 30°/s (accel 60°/s²), the others six times faster.
SLOW_J2 = replace(
    FAST,
    name="slow-j2",
    joint_speed_deg_s=(180.0, 30.0, 180.0, 180.0, 180.0, 180.0),
    joint_accel_deg_s2=(360.0, 60.0, 360.0, 360.0, 360.0, 360.0),
)


def test_a_joint_move_is_timed_by_its_slowest_joint() -> None:
    """With joints known, the move into pass 1 is a joint move: joint 2 turns 90° at
    30°/s (accel 60°/s²), so it sets the time, not the Cartesian path."""
    traj = two_passes_and_a_move()
    limits = SLOW_J2
    q = np.zeros((len(traj), 6))
    q[5:, 1] = np.radians(90.0)  # the move's last segment turns joint 2 by 90°
    q[5:, 0] = np.radians(10.0)  # joint 1 turns too, but faster
    ct = cycle_time(traj, spec_at(100.0), limits, joints_rad=q)
    a = limits.accel_mm_s2
    cartesian_before = 100.0 / 250.0 + 250.0 / a + 300.0 / 250.0 + 250.0 / a
    assert ct.move_s[0] == pytest.approx(cartesian_before + 90.0 / 30.0 + 30.0 / 60.0)
    assert ct.joint_moves == 1 and "1 joint moves" in ct.line()
    # Unknown joints (NaN) fall back to the Cartesian time.
    q[5] = np.nan
    fallback = cycle_time(traj, spec_at(100.0), limits, joints_rad=q)
    assert fallback.joint_moves == 0
    assert fallback.move_s[0] == pytest.approx(cartesian_before + 100.0 / 250.0 + 250.0 / a)


def test_a_pass_the_plan_enters_at_the_top_of_its_move_is_timed_so() -> None:
    """Where the plan records pass 1 entered at the first via point of the move into it
    (the fit's choice), the joint move is the segment into that point."""
    record = {"pass_entry_joints_deg": {"0": [0.0] * 6, "3": [0.0] * 6}}
    traj = replace(two_passes_and_a_move(), meta={"robot": record})
    np.testing.assert_array_equal(np.flatnonzero(pass_entries(traj)), [0, 3])
    limits = SLOW_J2
    q = np.zeros((len(traj), 6))
    q[3:, 1] = np.radians(90.0)  # the move's first segment turns joint 2 by 90°
    ct = cycle_time(traj, spec_at(100.0), limits, joints_rad=q)
    a = limits.accel_mm_s2
    cartesian_after = 300.0 / 250.0 + 250.0 / a + 100.0 / 250.0 + 250.0 / a
    assert ct.move_s[0] == pytest.approx(90.0 / 30.0 + 30.0 / 60.0 + cartesian_after)
    assert ct.joint_moves == 1


def test_a_program_stops_only_at_its_targets() -> None:
    """Timed on a program's thinned targets, a straight move's via point is no stop, and a
    pass keeps its time; runs stay apart though the poses between them are thinned away."""
    traj = two_passes_and_a_move()
    spec = spec_at(100.0, travel_mm_s=250.0)
    a = FAST.accel_mm_s2
    # Drop pass 0's middle pose and the move's second via point (200,300,100): the flown
    # move then goes up, then diagonally down to the start of pass 1.
    ct = cycle_time(traj, spec, FAST, targets=np.array([0, 2, 3, 5, 6, 7]))
    np.testing.assert_allclose(ct.pass_s, [2.0 + 100.0 / a, 2.0 + 100.0 / a])
    diagonal = math.hypot(300.0, 100.0)
    np.testing.assert_allclose(ct.move_s, [sum(d / 250 + 250 / a for d in (100.0, diagonal))])
    # Two runs of one pass with a gap of non-scanning poses, all thinned away.
    xyz = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0], [40, 0, 0]], float)
    gap = Trajectory(poses_at(xyz), [0] * 5, [True, True, False, True, True])
    ct = cycle_time(gap, spec, FAST, targets=np.array([0, 1, 3, 4]))
    assert ct.runs == 2 and ct.swaths == 1 and "in 1 pass (2 runs)" in ct.line()
    np.testing.assert_allclose(ct.move_s, [2.0 * math.sqrt(20.0 / a)])


def test_a_blended_move_is_one_trapezoid() -> None:
    """Blended through its via points, the move up, over and down is one profile over its
    500 mm; stopping at the first via point splits it in two."""
    traj = two_passes_and_a_move()
    spec = spec_at(100.0, travel_mm_s=250.0)
    a = FAST.accel_mm_s2
    blended = np.array([False, False, False, True, True, False, False, False])
    ct = cycle_time(traj, spec, FAST, blended=blended)
    np.testing.assert_allclose(ct.move_s, [500.0 / 250.0 + 250.0 / a])
    np.testing.assert_allclose(ct.pass_s, [2.0 + 100.0 / a] * 2)  # passes as before
    blended[3] = False
    ct = cycle_time(traj, spec, FAST, blended=blended)
    np.testing.assert_allclose(ct.move_s, [100.0 / 250 + 250 / a + 400.0 / 250 + 250 / a])
    with pytest.raises(ValueError, match="blended must be"):
        cycle_time(traj, spec, FAST, blended=blended[:3])


def test_a_view_costs_its_blended_raster_and_a_move_into_it() -> None:
    """What a view adds to a cycle: its passes and moves blended through every pose (two
    200 mm passes joined by a 500 mm move, each one trapezoid) and a move of `entry_mm`."""
    traj = two_passes_and_a_move()
    spec = spec_at(100.0, travel_mm_s=250.0)
    a = NOMINAL.accel_mm_s2
    raster = 2 * (200.0 / 100.0 + 100.0 / a) + 500.0 / 250.0 + 250.0 / a
    assert view_seconds(traj, spec, 0.0) == pytest.approx(raster, rel=1e-9)
    entry = 1000.0 / 250.0 + 250.0 / a
    assert view_seconds(traj, spec, 1000.0) == pytest.approx(raster + entry, rel=1e-9)


def test_json_and_limits_validation() -> None:
    data = cycle_time(two_passes_and_a_move(), ScanSpec(), NOMINAL).to_json_dict()
    assert data["passes"] == 2 and data["moves"] == 1 and data["limits"]["name"] == "nominal"
    assert data["total_s"] == pytest.approx(data["scanning_s"] + data["moving_s"])
    with pytest.raises(ValueError, match="joint_speed_deg_s"):
        replace(NOMINAL, joint_speed_deg_s=(1.0,) * 5)
    with pytest.raises(ValueError, match="accel_mm_s2"):
        MotionLimits("x", 1.0, 0.0, 1.0, 1.0, (1.0,) * 6, (1.0,) * 6)


def raster(length_mm: float = 200.0, passes: int = 2, n: int = 30) -> Trajectory:
    """Boustrophedon passes along x, 60 mm apart at z = 150 mm, sensor down."""
    poses, swath = [], []
    for k in range(passes):
        y = (k - (passes - 1) / 2) * 60.0
        a, b = np.array([-length_mm / 2, y, 150.0]), np.array([length_mm / 2, y, 150.0])
        a, b = (b, a) if k % 2 else (a, b)
        u = (b - a) / np.linalg.norm(b - a)
        sw = Swath(k, a, b, u, np.cross([0, 0, 1.0], u))
        poses.append(sw.poses(np.linspace(0, length_mm, n), np.zeros(n), np.zeros(n)))
        swath.append(np.full(n, k))
    return Trajectory(np.concatenate(poses), np.concatenate(swath), np.ones(passes * n, bool))


def test_export_prints_the_cycle_time_on_the_chosen_arm(tmp_path) -> None:
    """On the KR 6 (standing on the table top beside the plate) the move into the second pass is a
    joint move; with --robot none the nominal arm times it, and the output says so."""
    plan = tmp_path / "t.csv"
    traj = raster()
    write_csv(traj, plan)
    args = ["export", str(plan), "--format", "krl", "--tcp", "0,0,90,0,0,0"]
    args += ["--part-pose", "355.966,0,-40,0,0,0", "-o", str(tmp_path / "p.src")]
    result = run_cli(*args, "--robot", "kr6-r900", "--part", plate_file(tmp_path))
    assert result.exit_code == 0, result.output
    (line,) = [ln for ln in result.stdout.splitlines() if ln.startswith("cycle time ")]
    assert line.endswith("in 2 passes, moving 0.9 s, 1 joint moves; trapezoidal, kr6-r900 limits)")
    scanning = cycle_time(traj, ScanSpec(), motion_limits("kr6-r900")).scanning_s
    assert f"(scanning {scanning:.1f} s in 2 passes" in line
    result = run_cli(*args, "--robot", "none")
    assert result.exit_code == 0, result.output
    (line,) = [ln for ln in result.stdout.splitlines() if ln.startswith("cycle time ")]
    expected = cycle_time(traj, ScanSpec(), NOMINAL).line()
    assert line == expected + ", --robot none: timed on a nominal arm"
    assert "nominal limits" in line
