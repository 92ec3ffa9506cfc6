"""Every robot-program dialect parsed back and compared with the trajectory it came from."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from scanplan.export import (
    FORMATS,
    ExportOptions,
    export_program,
    flange_poses,
    parse_pose_arg,
    parse_program,
    parse_program_details,
)
from scanplan.export.common import plan_motion
from scanplan.trajectory import Trajectory


def snake_trajectory() -> Trajectory:
    """Three snake passes over a bumpy part: pitch varies along each pass, the sensor turns
    180° about its axis between passes, transitions lift clear and are not scanned."""
    poses, swath, scanning = [], [], []

    def add(xyz, yaw, pitch, k, scan):
        T = np.eye(4)
        down = Rotation.from_euler("zx", [yaw, np.pi]) * Rotation.from_euler("x", pitch)
        T[:3, :3], T[:3, 3] = down.as_matrix(), xyz
        poses.append(T)
        swath.append(k)
        scanning.append(scan)

    for k in range(3):
        sign = 1 if k % 2 == 0 else -1
        y = 400.0 * k
        x0, x1 = (-20.0, 30.0) if sign > 0 else (30.0, -20.0)
        add([x0, y, 600.0], 0.0 if sign > 0 else np.pi, 0.0, k, False)  # transition, lifted
        xs = np.arange(x0, x1 + sign * 1e-9, sign * 0.5)
        for x in xs:
            z = 400.0 + 5.0 * np.sin(x / 7.0)
            pitch = 0.3 * np.cos(x / 7.0)
            add([x, y + 0.1 * x, z], 0.0 if sign > 0 else np.pi, pitch, k, True)
        add([x1, y, 600.0], 0.0 if sign > 0 else np.pi, 0.0, k, False)
    return Trajectory(np.array(poses), swath, scanning)


TRAJ = snake_trajectory()
OPTIONS = ExportOptions(
    part_pose=parse_pose_arg("500,-200,100,30,5,-10"),
    tcp=parse_pose_arg("12,-3,180,0,-15,90"),
    travel_speed_mm_s=300.0,
    blend_mm=0.2,
)


def _rot_err(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of a⁻¹b, immune to quaternion sign."""
    return (
        Rotation.from_matrix(a[:, :3, :3]).inv() * Rotation.from_matrix(b[:, :3, :3])
    ).magnitude()


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_round_trip(fmt: str) -> None:
    text = export_program(TRAJ, fmt, OPTIONS)
    poses, scanning = parse_program(text, fmt)
    expected = OPTIONS.part_pose @ TRAJ.poses
    assert poses.shape == expected.shape
    assert np.abs(poses[:, :3, 3] - expected[:, :3, 3]).max() < 1e-3  # 1e-6 m
    assert _rot_err(poses, expected).max() < 1e-6
    np.testing.assert_array_equal(scanning, TRAJ.scanning)

    details = parse_program_details(text, fmt)
    motion = plan_motion(TRAJ, OPTIONS)
    np.testing.assert_allclose(details.speed_mm_s, motion.speed_mm_s, rtol=1e-5)
    if details.blended is not None:
        np.testing.assert_array_equal(details.blended, motion.blend_mm > 0)


def test_motion_rules() -> None:
    m = plan_motion(TRAJ, OPTIONS)
    runs = int(m.pass_start.sum())
    assert runs == 3 == int(m.pass_end.sum())
    ends = m.pass_start | m.pass_end | ~m.scanning
    assert np.all(m.blend_mm[ends] == 0)
    # 0.5 mm between stations: blends capped at half a segment so neighbours never overlap.
    inner = m.blend_mm[~ends]
    assert inner.max() <= 0.2 + 1e-12 and inner.min() > 0
    assert np.all(m.speed_mm_s[m.scanning & ~m.pass_start] == 100.0)  # 200 Hz · 0.5 mm
    assert np.all(m.speed_mm_s[~m.scanning | m.pass_start] == 300.0)


def test_urscript_structure() -> None:
    text = export_program(TRAJ, "urscript", OPTIONS)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    code = [ln for ln in lines if not ln.startswith("#")]
    assert code[0] == "def scanplan_path():" and code[-2] == "end"
    assert code[-1] == "scanplan_path()"
    movel = re.findall(r"movel\(p\[[^\]]*\], a=([^,]+), v=([^,]+), r=([^)]+)\)", text)
    assert len(movel) == len(TRAJ)
    m = plan_motion(TRAJ, OPTIONS)
    r = np.array([float(x[2]) for x in movel])
    assert np.all(r[m.pass_start | m.pass_end | ~m.scanning] == 0)
    np.testing.assert_allclose(r, m.blend_mm / 1000, atol=1e-9)
    v = {float(x[1]) for x in movel}
    assert v == {0.1, 0.3}
    assert {float(x[0]) for x in movel} == {1.0}
    assert len(re.findall(r"# pass \d+ start", text)) == 3
    assert len(re.findall(r"# pass \d+ end", text)) == 3
    tcp = re.search(r"set_tcp\(p\[([^\]]*)\]\)", text)
    assert tcp is not None
    vals = np.array([float(x) for x in tcp.group(1).split(",")])
    np.testing.assert_allclose(vals[:3], OPTIONS.tcp[:3, 3] / 1000, atol=1e-9)
    R = Rotation.from_rotvec(vals[3:]).as_matrix()
    np.testing.assert_allclose(R, OPTIONS.tcp[:3, :3], atol=1e-8)


def test_rapid_structure() -> None:
    text = export_program(TRAJ, "rapid", OPTIONS)
    assert text.startswith("MODULE scanplan_path") and text.rstrip().endswith("ENDMODULE")
    assert "PROC main()" in text and "ENDPROC" in text
    moves = re.findall(r"MoveL (\w+), (\w+), (\w+), tSensor\\WObj:=wobj0;", text)
    assert len(moves) == len(TRAJ)
    m = plan_motion(TRAJ, OPTIONS)
    zones = np.array([z for _, _, z in moves])
    assert np.all(zones[m.pass_start | m.pass_end | ~m.scanning] == "fine")
    assert np.all(zones[m.blend_mm > 0] == "zScan")
    tool = re.search(r"tooldata tSensor := \[TRUE,\[\[([^\]]*)\],\[([^\]]*)\]\]", text)
    assert tool is not None
    np.testing.assert_allclose([float(v) for v in tool.group(1).split(",")], [12, -3, 180])
    q = np.array([float(v) for v in tool.group(2).split(",")])
    R = Rotation.from_quat([*q[1:], q[0]]).as_matrix()
    np.testing.assert_allclose(R, OPTIONS.tcp[:3, :3], atol=1e-8)


def test_krl_structure() -> None:
    text = export_program(TRAJ, "krl", OPTIONS)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    assert "DEF scanplan_path( )" in lines and lines[-1] == "END"
    lins = [ln for ln in lines if ln.startswith("LIN ")]
    assert len(lins) == len(TRAJ)
    m = plan_motion(TRAJ, OPTIONS)
    blended = np.array([ln.endswith("C_DIS") for ln in lins])
    np.testing.assert_array_equal(blended, m.blend_mm > 0)
    assert not blended[m.pass_start | m.pass_end].any()
    assert (
        "$TOOL = {X 12.000000,Y -3.000000,Z 180.000000,A 0.000000,B -15.000000,C 90.000000}"
        in lines
    )
    assert {ln for ln in lines if ln.startswith("$VEL.CP")} == {"$VEL.CP = 0.1", "$VEL.CP = 0.3"}


def test_krl_angles_are_intrinsic_zyx() -> None:
    T = np.eye(4)
    T[:3, :3] = (
        Rotation.from_euler("z", 30, degrees=True)
        * Rotation.from_euler("y", 20, degrees=True)
        * Rotation.from_euler("x", 10, degrees=True)
    ).as_matrix()
    text = export_program(Trajectory(T[None], [0], [True]), "krl", ExportOptions())
    assert "LIN {X 0.000000,Y 0.000000,Z 0.000000,A 30.000000,B 20.000000,C 10.000000}" in text


def test_ros_structure() -> None:
    text = export_program(TRAJ, "ros", OPTIONS)
    doc = yaml.safe_load(text)
    assert doc["pose_array"]["header"]["frame_id"] == "base_link"
    assert len(doc["pose_array"]["poses"]) == len(doc["path"]["poses"]) == len(TRAJ)
    first = doc["pose_array"]["poses"][0]
    np.testing.assert_allclose(
        [first["position"][k] for k in "xyz"],
        (OPTIONS.part_pose @ TRAJ.poses[0])[:3, 3] / 1000,
        atol=1e-9,
    )
    stamps = [p["header"]["stamp"] for p in doc["path"]["poses"]]
    t = np.array([s["sec"] + s["nanosec"] * 1e-9 for s in stamps])
    assert t[0] == 0 and np.all(np.diff(t) >= 0)
    # One scan step of 0.5 mm at 100 mm/s takes 5 ms.
    i = int(np.flatnonzero(TRAJ.scanning)[1])
    assert t[i] - t[i - 1] == pytest.approx(
        np.linalg.norm(np.diff(TRAJ.positions_mm[i - 1 : i + 1], axis=0)) / 100, abs=1e-8
    )


def test_csv_header_and_frame() -> None:
    text = export_program(TRAJ, "csv", ExportOptions(part_pose=parse_pose_arg("10,20,30,0,0,0")))
    header, first = text.splitlines()[:2]
    assert header == "swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz,speed_mm_s,blend_mm"
    cells = [float(c) for c in first.split(",")]
    np.testing.assert_allclose(cells[2:5], TRAJ.positions_mm[0] + [10, 20, 30], atol=1e-6)


def test_flange_poses_compose_with_tcp() -> None:
    flange = flange_poses(TRAJ, OPTIONS)
    np.testing.assert_allclose(flange @ OPTIONS.tcp, OPTIONS.part_pose @ TRAJ.poses, atol=1e-9)


def test_parse_pose_arg() -> None:
    T = parse_pose_arg(" 1, 2 ,3,30,20,10")
    expected = Rotation.from_euler("ZYX", [30, 20, 10], degrees=True).as_matrix()
    np.testing.assert_allclose(T[:3, :3], expected)
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])
    # Intrinsic ZYX = Rz(A) Ry(B) Rx(C).
    Rz = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    Ry = Rotation.from_euler("y", 20, degrees=True).as_matrix()
    Rx = Rotation.from_euler("x", 10, degrees=True).as_matrix()
    np.testing.assert_allclose(T[:3, :3], Rz @ Ry @ Rx, atol=1e-12)
    for bad in ("1,2,3", "1,2,3,4,5,x", "1,2,3,4,5,nan", ""):
        with pytest.raises(ValueError, match="pose"):
            parse_pose_arg(bad)


def test_bad_options_and_format() -> None:
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(ValueError, match="part pose"):
        ExportOptions(part_pose=skew)
    with pytest.raises(ValueError, match="program name"):
        ExportOptions(program_name="1 bad")
    with pytest.raises(ValueError, match="travel_speed_mm_s"):
        ExportOptions(travel_speed_mm_s=0)
    with pytest.raises(ValueError, match="unknown export format"):
        export_program(TRAJ, "gcode", OPTIONS)
    with pytest.raises(ValueError, match="no movel"):
        parse_program("def x():\nend\n", "urscript")
