"""A plan's program: its language follows the arm or the file name, and a mismatch is
refused; its options are the plan's ScanSpec, arm, part pose and TCP."""

from __future__ import annotations

from pathlib import Path

import pytest

from scanplan.robot.program import program_format


@pytest.mark.parametrize(
    ("fmt", "output", "robot", "expected"),
    [
        (None, "p.src", "kr6-r900", "krl"),
        (None, "p", "kr6-r900", "krl"),  # no extension: the arm's language
        (None, "p", "ur5e", "urscript"),
        (None, "p", "irb2400", "rapid"),
        (None, "p.mod", None, "rapid"),  # no arm: the extension
        (None, "p", None, "csv"),  # no arm, no extension: the table
        (None, "p", "none", "csv"),
        ("ros", "p.yaml", "kr6-r900", "ros"),  # any arm's integrator reads ROS and CSV
        ("csv", "p.csv", "ur5e", "csv"),
        ("rosbag2", "bag", "irb2400", "rosbag2"),
        ("krl", "p.src", "kr6-r900", "krl"),
    ],
)
def test_the_language_follows_the_arm_or_the_file(fmt, output, robot, expected):
    assert program_format(fmt, Path(output), robot) == expected


@pytest.mark.parametrize(
    ("fmt", "output", "robot", "message"),
    [
        ("krl", "p.src", "ur5e", "not the language of ur5e's controller (urscript)"),
        ("urscript", "p.src", "kr6-r900", "a .src file holds krl, not urscript"),
        (None, "p.script", "kr6-r900", "not the language of kr6-r900's controller"),
        (None, "p.src", "irb2400", "not the language of irb2400's controller (rapid)"),
        ("rapid", "p.script", None, "a .script file holds urscript, not rapid"),
        (None, "p", "lrmate200id", "give --format"),  # an arm whose language we do not write
        (None, "p", "my_arm.toml", "give --format"),
        ("kuka", "p.src", None, "unknown format 'kuka'"),
    ],
)
def test_a_program_in_the_wrong_language_is_refused(fmt, output, robot, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        program_format(fmt, Path(output), robot)
