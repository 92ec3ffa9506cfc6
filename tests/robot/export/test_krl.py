"""KUKA KRL: one LIN per thinned target, blends, the tool, intrinsic ZYX angles, the
acquisition output, PTP into each pass with Status and Turn."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.core.trajectory import Trajectory
from scanplan.robot import get_robot
from scanplan.robot.export import (
    ExportOptions,
    export_program,
    parse_program,
)
from scanplan.robot.export.common import plan_motion
from scanplan.robot.export.krl import status_turn
from scanplan.robot.export.rotations import pose_from_xyzabc

TRAJ = snake_trajectory()


def test_krl_structure() -> None:
    text = export_program(TRAJ, "krl", OPTIONS)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    assert "DEF scanplan_path( )" in lines and lines[-1] == "END"
    lins = [ln for ln in lines if ln.startswith("LIN ")]
    m = plan_motion(TRAJ, OPTIONS)
    assert len(lins) == len(m.poses) < len(TRAJ)
    # The targets are in the part's frame, $BASE the part's pose in the base frame.
    base = next(ln for ln in lines if ln.startswith("$BASE = "))
    assert base.startswith("$BASE = {X 500.000000,Y -200.000000,Z 100.000000,A 30.0")
    first = [float(v.split()[1]) for v in lins[0][5:-1].split(",")[:3]]
    # ... and are the TCP: the laser line, W_d along the sensor's beam.
    line = TRAJ.poses[0] @ OPTIONS.scan.T_sensor_line
    np.testing.assert_allclose(first, line[:3, 3], atol=1e-5)
    blended = np.array([ln.endswith("C_DIS") for ln in lins])
    np.testing.assert_array_equal(blended, m.blend_mm > 0)
    assert not blended[m.pass_start | m.pass_end].any()
    # $TOOL is that point on the sensor: T_flange_sensor moved W_d along the beam.
    tool = next(ln for ln in lines if ln.startswith("$TOOL = {"))
    items = dict(item.split() for item in tool[len("$TOOL = {") : -1].split(","))
    T_tool = pose_from_xyzabc(float(items[k]) for k in "XYZABC")
    np.testing.assert_allclose(T_tool, OPTIONS.tcp @ OPTIONS.scan.T_sensor_line, atol=1e-5)
    assert "; TCP standoff 400 mm along the sensor's beam" in text
    assert {ln for ln in lines if ln.startswith("$VEL.CP")} == {"$VEL.CP = 0.1", "$VEL.CP = 0.3"}
    # Acquisition on right after each pass's first target, off right after its last.
    on = [i for i, ln in enumerate(lines) if ln.startswith("$OUT[1] = TRUE")]
    off = [i for i, ln in enumerate(lines) if ln.startswith("$OUT[1] = FALSE")]
    assert len(on) == len(off) == 3
    starts, ends = np.flatnonzero(m.pass_start), np.flatnonzero(m.pass_end)
    assert [lines[i - 1] for i in on] == [lins[j] for j in starts]
    assert [lines[i - 1] for i in off] == [lins[j] for j in ends]


def test_krl_angles_are_intrinsic_zyx() -> None:
    T = np.eye(4)
    T[:3, :3] = (
        Rotation.from_euler("z", 30, degrees=True)
        * Rotation.from_euler("y", 20, degrees=True)
        * Rotation.from_euler("x", 10, degrees=True)
    ).as_matrix()
    text = export_program(Trajectory(T[None], [0], [True]), "krl", ExportOptions())
    assert "A 30.000000,B 20.000000,C 10.000000}\n" in text


def test_krl_enters_passes_by_ptp_with_status_and_turn() -> None:
    arm = get_robot("kr6-r900")
    q = np.radians([20.0, -100.0, 110.0, 30.0, 50.0, -40.0])  # in front, elbow up, A5 > 0
    T_base_sensor = arm.forward(q) @ OPTIONS.tcp
    poses = np.tile(np.linalg.inv(OPTIONS.part_pose) @ T_base_sensor, (3, 1, 1))
    poses[:, 0, 3] += [0.0, 5.0, 10.0]
    options = replace(OPTIONS, joints_rad=np.tile(q, (3, 1)), arm=arm)
    text = export_program(Trajectory(poses, [0] * 3, [True] * 3), "krl", options)
    moves = [ln.strip() for ln in text.splitlines() if ln.strip().startswith(("LIN", "PTP"))]
    assert moves[0].startswith("PTP {X ") and all(m.startswith("LIN ") for m in moves[1:])
    items = dict(item.split() for item in moves[0][5:-1].split(","))
    # Forward kinematics of the joints reproduces the Cartesian target ($BASE, $TOOL).
    target = pose_from_xyzabc(float(items[k]) for k in "XYZABC")
    np.testing.assert_allclose(OPTIONS.part_pose @ target @ np.linalg.inv(OPTIONS.tool),
                               arm.forward(q), atol=1e-5)  # fmt: skip
    # Basic area, A3 >= phi, A5 > 0; A2 and A6 negative.
    assert (items["S"], items["T"]) == ("'B010'", "'B100010'")
    assert parse_program(text, "krl")[0].shape == (2, 4, 4)  # one straight move: its ends


def test_status_bits() -> None:
    arm = get_robot("kr6-r900")
    q = np.radians([20.0, -100.0, 110.0, 30.0, 50.0, -40.0])
    s, t = status_turn(q, arm)
    assert (s, t) == (0b010, 0b100010)
    flip = q * [1, 1, 1, 1, -1, 1]
    assert status_turn(flip, arm) == (s ^ 0b100, t ^ 0b010000)  # A5's sign: S bit 2, T bit 4
    # Leaning back past the column: the wrist root point behind A1, the overhead area.
    assert status_turn(np.radians([0.0, -150.0, 60.0, 0.0, 40.0, 0.0]), arm)[0] == 0b011
    # A3 below phi (the arm folded back beyond stretched): bit 1 clear.
    assert status_turn(np.radians([0.0, -60.0, -30.0, 0.0, 40.0, 0.0]), arm)[0] & 0b010 == 0
    # The eight inverse-kinematics branches of one pose: eight different Status values.
    branches = arm.inverse(arm.forward(q)[None])[0]
    assert np.isfinite(branches).all()
    assert len({status_turn(b, arm)[0] for b in branches}) == 8
