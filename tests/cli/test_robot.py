"""`scanplan export` on the command line: every format parsed back, a ROS 2 bag, bad options
in one line with no output left behind, a device or FIFO as -o written into or refused."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import listing, plate_file, run_cli, snake_trajectory
from scanplan.cli import app
from scanplan.core.files import output_kind
from scanplan.core.plan_file import write_csv
from scanplan.robot.export import ExportOptions, parse_pose_arg, parse_program
from scanplan.robot.export.common import plan_motion

TRAJ = snake_trajectory()


@pytest.mark.parametrize("fmt", ["urscript", "rapid", "krl", "ros", "csv"])
def test_export_every_format(plate_and_trajectory, tmp_path, fmt):
    from scanplan.core.plan_file import read_csv

    _, traj_path = plate_and_trajectory
    out = tmp_path / f"prog.{fmt}"
    # The format alone: the reach check (tests/robot/test_place.py) is switched off, and says so.
    result = run_cli(
        "export", str(traj_path), "--format", fmt, "--robot", "none",
        "--part-pose", "500,0,-200,0,0,0", "-o", str(out),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "--robot none: no reach check" in result.output
    poses, scanning = parse_program(out.read_text(), fmt)
    traj = read_csv(traj_path)
    motion = plan_motion(traj, ExportOptions())  # the thinned targets (in the part's frame)
    assert f"{fmt}: {len(motion.poses)} targets from {len(traj)} planned poses" in result.output
    expected = traj.poses[motion.source].copy()
    expected[:, :3, 3] += (500, 0, -200)
    assert np.allclose(poses[:, :3, 3], expected[:, :3, 3], atol=1e-3)
    assert scanning.all()


def test_export_bad_pose_leaves_no_file(plate_and_trajectory, tmp_path):
    _, traj_path = plate_and_trajectory
    out = tmp_path / "prog.script"
    result = run_cli("export", str(traj_path), "--tcp", "1,2,three", "-o", str(out))
    assert result.exit_code == 2
    assert "error:" in result.output
    assert not out.exists()


@pytest.mark.parametrize(
    ("command", "option", "pose", "message"),
    [
        ("export", "--tcp", "1e308,0,0,0,0,0", "x 1e+308 is not in [-5000, 5000] mm"),
        ("export", "--part-pose", "0,0,1e308,0,0,0", "z 1e+308 is not in [-100000, 100000] mm"),
        ("place", "--tcp", "0,0,6000,0,0,0", "z 6000 is not in [-5000, 5000] mm"),
        ("view", "--part-pose", "0,0,0,0,1e300,0", "B 1e+300 is not in [-360, 360] deg"),
        ("plan", "--part-pose", "1e308,0,0,0,0,0", "x 1e+308 is not in [-100000, 100000] mm"),
    ],
)
def test_implausible_poses_name_the_option(tmp_path, command, option, pose, message):
    # Nothing is read: the option is refused while the command line is parsed.
    out = tmp_path / "out"
    source = "plate" if command == "plan" else str(tmp_path / "plan.json")
    output = [] if command == "place" else ["-o", str(out)]
    result = run_cli(command, source, *output, "--robot", "ur5e", option, pose)
    assert result.exit_code == 2 and len(result.stderr.splitlines()) <= 2, result.stderr
    assert f"{option}: pose {pose!r}: {message}" in result.stderr
    assert "reach" not in result.stderr and not out.exists()


def test_cli_export_rosbag2(tmp_path, monkeypatch) -> None:
    from rosbags.rosbag2 import Writer

    from scanplan.robot.export.rosbag import read_rosbag

    traj_path = tmp_path / "t.csv"
    write_csv(TRAJ, traj_path)
    out = tmp_path / "out_bag"
    args = ["export", str(traj_path), "--format", "rosbag2", "-o", str(out)]
    # The part placed so that the arm's base stands beside its table, not in it.
    part_pose = "600,-300,100,30,5,-10"
    poses = ["--part-pose", part_pose, "--tcp", "12,-3,180,0,-15,90"]
    runner = CliRunner()
    robot = ["--robot", "ur5e", "--allow-unreachable", "--part", plate_file(tmp_path)]
    frame = ["--ros-frame", "door"]
    result = runner.invoke(app, [*args, *poses, *robot, *frame, "--travel-speed", "300"])
    assert result.exit_code == 0, result.output
    assert "ur5e: " in result.output  # the UR5e reach check ran (ok or a warning)
    motion = plan_motion(TRAJ, OPTIONS)
    assert f"rosbag2: {len(motion.poses)} targets from {len(TRAJ)} planned poses" in result.output
    contents = read_rosbag(out)
    # Read back as the sensor's poses.
    expected = parse_pose_arg(part_pose) @ TRAJ.poses[motion.source]
    assert np.abs(contents.poses[:, :3, 3] - expected[:, :3, 3]).max() <= 1e-6
    np.testing.assert_array_equal(contents.speed_mm_s, plan_motion(TRAJ, OPTIONS).speed_mm_s)
    # The targets in the part's frame, which the part pose places as one static transform.
    assert contents.frame_id == "door" and contents.transforms[0][:2] == ("base_link", "door")
    np.testing.assert_allclose(contents.transforms[0][2], parse_pose_arg(part_pose), atol=1e-6)

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
    assert result.exit_code == 2
    assert result.stderr == f"error: cannot write rosbag2 {bad}: disk full\n"
    assert listing(tmp_path) == ["out_bag", "plate.stl", "t.csv", "taken"]


def test_export_never_overwrites_its_plan_and_its_csv_is_not_taken_for_a_plan(tmp_path):
    plan = tmp_path / "plan.csv"
    write_csv(TRAJ, plan)
    before = plan.read_text()
    result = run_cli("export", str(plan), "--format", "csv", "--robot", "none", "-o", str(plan))
    assert result.exit_code == 2 and "is the plan being exported" in result.stderr
    assert plan.read_text() == before
    program = tmp_path / "program.csv"
    result = run_cli("export", str(plan), "--format", "csv", "--robot", "none", "-o", str(program))
    assert result.exit_code == 0, result.output
    result = run_cli("evaluate", "drone", str(program), "--points", "64")
    assert result.exit_code == 2
    assert "robot program exported as CSV" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_export_into_a_device_or_fifo_never_replaces_it(plate_and_trajectory, tmp_path):
    # `-o /dev/stdout`, `-o /dev/null` or a link to one: written into, never swapped for a
    # regular file (as root that would break the system's /dev/null); a FIFO nobody reads
    # is refused at once rather than waited on.
    _, traj_path = plate_and_trajectory
    args = ["export", str(traj_path), "--format", "csv", "--robot", "none"]
    link = tmp_path / "null.csv"
    link.symlink_to("/dev/null")
    assert output_kind(link) == "character device"  # so the writer opens it, never renames
    result = run_cli(*args, "-o", str(link))
    assert result.exit_code == 0, result.output
    assert os.readlink(link) == "/dev/null" and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    result = run_cli(*args, "-o", str(fifo))
    assert result.exit_code == 2
    assert result.stderr.splitlines()[-1] == (
        f"error: output {fifo} is a FIFO that nobody reads; not writing to it"
    )
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert listing(tmp_path) == ["null.csv", "pipe.csv", "plate.stl", "t.csv"]
