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
from scanplan.quantities import ScanSpec
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
    scan=ScanSpec(travel_speed_mm_s=300.0),
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
        ExportOptions(scan=ScanSpec(travel_speed_mm_s=0))
    with pytest.raises(ValueError, match="unknown export format"):
        export_program(TRAJ, "gcode", OPTIONS)
    with pytest.raises(ValueError, match="no movel"):
        parse_program("def x():\nend\n", "urscript")


# --- rosbag2 -------------------------------------------------------------------------------


def _bag_messages(path) -> dict[str, tuple[str, int, object]]:
    """{topic: (msgtype, message count, the message)} read with rosbags' own Reader."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    out = {}
    with Reader(path) as reader:
        assert reader.message_count == 2
        for conn, timestamp, raw in reader.messages():
            assert timestamp == 0 and conn.topic not in out
            out[conn.topic] = (
                conn.msgtype,
                conn.msgcount,
                store.deserialize_cdr(raw, conn.msgtype),
            )
    return out


def _listing(directory) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_rosbag_round_trip(tmp_path) -> None:
    from scanplan.export import export_rosbag
    from scanplan.export.rosbag import read_rosbag

    bag = tmp_path / "scan_bag"
    export_rosbag(TRAJ, bag, OPTIONS)
    assert _listing(tmp_path) == ["scan_bag"]  # no staging directory left beside it
    assert _listing(bag) == ["metadata.yaml", "scan_bag.db3"]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "sqlite3"

    msgs = _bag_messages(bag)
    assert set(msgs) == {"/scanplan/path", "/scanplan/poses"}
    path_type, path_count, path = msgs["/scanplan/path"]
    poses_type, poses_count, pose_array = msgs["/scanplan/poses"]
    assert (path_type, poses_type) == ("nav_msgs/msg/Path", "geometry_msgs/msg/PoseArray")
    assert path_count == poses_count == 1
    assert pose_array.header.frame_id == path.header.frame_id == "base_link"
    assert len(pose_array.poses) == len(path.poses) == len(TRAJ)

    expected = OPTIONS.part_pose @ TRAJ.poses
    for poses in (pose_array.poses, [p.pose for p in path.poses]):
        xyz = np.array([[p.position.x, p.position.y, p.position.z] for p in poses])
        xyzw = np.array([[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
                         for p in poses])  # fmt: skip
        assert np.abs(xyz - expected[:, :3, 3] / 1000).max() <= 1e-9
        R = Rotation.from_quat(xyzw).as_matrix()
        assert np.abs(R - expected[:, :3, :3]).max() <= 1e-9
        assert np.all(xyzw[:, 3] >= 0)  # the same canonical sign as the YAML export

    # Path stamps: the YAML export's planned arrival times, to the nanosecond.
    doc = yaml.safe_load(export_program(TRAJ, "ros", OPTIONS))
    yaml_stamps = [
        (s["sec"], s["nanosec"]) for s in (p["header"]["stamp"] for p in doc["path"]["poses"])
    ]
    bag_stamps = [(p.header.stamp.sec, p.header.stamp.nanosec) for p in path.poses]
    assert bag_stamps == yaml_stamps
    assert bag_stamps[-1][0] > 0  # the path takes seconds: the stamps are not all zero
    assert {p.header.frame_id for p in path.poses} == {"base_link"}

    contents = read_rosbag(bag)
    assert np.abs(contents.poses[:, :3, 3] - expected[:, :3, 3]).max() <= 1e-6  # mm: 1e-9 m
    assert _rot_err(contents.poses, expected).max() < 1e-9
    motion = plan_motion(TRAJ, OPTIONS)
    np.testing.assert_array_equal(contents.scanning, TRAJ.scanning)
    np.testing.assert_array_equal(contents.swath, TRAJ.swath)
    np.testing.assert_array_equal(contents.speed_mm_s, motion.speed_mm_s)
    assert contents.frame_id == "base_link"
    assert contents.topics == {"/scanplan/path": path_type, "/scanplan/poses": poses_type}
    assert contents.message_counts == {"/scanplan/path": 1, "/scanplan/poses": 1}


def test_rosbag_frame_id_and_replacing(tmp_path) -> None:
    from scanplan.export import export_rosbag
    from scanplan.export.rosbag import read_rosbag

    bag = tmp_path / "bag"
    export_rosbag(TRAJ, bag, OPTIONS)
    # A second export replaces the bag, as the text formats overwrite their file.
    short = Trajectory(TRAJ.poses[:5], TRAJ.swath[:5], TRAJ.scanning[:5])
    export_rosbag(short, bag, ExportOptions(ros_frame_id="world"))
    contents = read_rosbag(bag)
    assert len(contents.poses) == 5 and contents.frame_id == "world"
    np.testing.assert_allclose(contents.poses, short.poses, atol=1e-6)
    assert _listing(tmp_path) == ["bag"] and _listing(bag) == ["bag.db3", "metadata.yaml"]


def test_rosbag_refuses_to_replace_other_things(tmp_path) -> None:
    from scanplan.export import export_rosbag

    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "keep.txt").write_text("mine")
    (tmp_path / "file").write_text("also mine")
    for name in ("notes", "file"):
        with pytest.raises(ValueError, match="not a rosbag2 directory"):
            export_rosbag(TRAJ, tmp_path / name, OPTIONS)
    assert (tmp_path / "notes" / "keep.txt").read_text() == "mine"
    assert (tmp_path / "file").read_text() == "also mine"
    assert _listing(tmp_path) == ["file", "notes"]


def test_rosbag_failure_mid_write_leaves_nothing(tmp_path, monkeypatch) -> None:
    from rosbags.rosbag2 import Writer

    from scanplan.export import export_rosbag
    from scanplan.export.rosbag import read_rosbag

    bag = tmp_path / "bag"
    export_rosbag(Trajectory(TRAJ.poses[:3], [0, 0, 0], [True] * 3), bag, OPTIONS)
    real_write = Writer.write
    calls = []

    def failing_write(self, connection, timestamp, data):
        calls.append(connection.topic)
        if connection.topic == "/scanplan/poses":  # the second message of each bag
            raise OSError("No space left on device")
        real_write(self, connection, timestamp, data)

    monkeypatch.setattr(Writer, "write", failing_write)
    with pytest.raises(OSError, match="No space"):
        export_rosbag(TRAJ, tmp_path / "new_bag", OPTIONS)
    with pytest.raises(OSError, match="No space"):
        export_rosbag(TRAJ, bag, OPTIONS)
    assert len(calls) == 4
    assert _listing(tmp_path) == ["bag"]  # no new bag, no staging directory
    assert len(read_rosbag(bag).poses) == 3  # the old bag is intact


def test_cli_export_rosbag2(tmp_path, monkeypatch) -> None:
    from rosbags.rosbag2 import Writer
    from typer.testing import CliRunner

    from scanplan.cli import app
    from scanplan.export.rosbag import read_rosbag
    from scanplan.trajectory import write_csv

    traj_path = tmp_path / "t.csv"
    write_csv(TRAJ, traj_path)
    out = tmp_path / "out_bag"
    args = ["export", str(traj_path), "--format", "rosbag2", "-o", str(out)]
    poses = ["--part-pose", "500,-200,100,30,5,-10", "--tcp", "12,-3,180,0,-15,90"]
    runner = CliRunner()
    result = runner.invoke(app, [*args, *poses, "--travel-speed", "300"])
    assert result.exit_code == 0, result.output
    assert "reach" in result.output  # the UR5e reach check ran (ok or a warning)
    assert f"rosbag2: {len(TRAJ)} poses" in result.output
    contents = read_rosbag(out)
    expected = OPTIONS.part_pose @ TRAJ.poses
    assert np.abs(contents.poses[:, :3, 3] - expected[:, :3, 3]).max() <= 1e-6
    np.testing.assert_array_equal(contents.speed_mm_s, plan_motion(TRAJ, OPTIONS).speed_mm_s)

    # User errors: one line, exit 2, no traceback, no directory (nor staging) left behind.
    bad = tmp_path / "bad_bag"
    for extra in (["--tcp", "1,2,three"], ["--format", "rosbag3"]):
        result = runner.invoke(app, [*args[:-1], str(bad), *extra])
        assert result.exit_code == 2
        assert result.output.startswith("error:") and result.output.strip().count("\n") == 0
    assert "rosbag2" in result.output  # the unknown-format message lists it
    (tmp_path / "taken").write_text("x")
    result = runner.invoke(app, [*args[:-1], str(tmp_path / "taken"), "--robot", "none"])
    assert result.exit_code == 2 and "not a rosbag2 directory" in result.output
    monkeypatch.setattr(Writer, "write", lambda *a: (_ for _ in ()).throw(OSError("disk full")))
    result = runner.invoke(app, [*args[:-1], str(bad), "--robot", "none"])
    assert result.exit_code == 2 and result.output == "error: disk full\n"
    assert _listing(tmp_path) == ["out_bag", "t.csv", "taken"]
