"""Motion limits per arm: every preset has its data sheet's, a user's TOML arm its own or the
nominal arm's."""

from __future__ import annotations

import os

import numpy as np
import pytest

from scanplan.core.cycle import NOMINAL
from scanplan.robot import MOTION_LIMITS, ROBOT_NAMES, get_robot, motion_limits
from scanplan.robot.export.rotations import pose_from_xyzabc
from scanplan.robot.hints import across_flange

ARM = """
name = "my-arm"
a1 = 25
a2 = -35
c1 = 400
c2 = 455
c3 = 420
c4 = 80
limits_deg = [[-170, 170], [-190, 45], [-120, 156], [-185, 185], [-120, 120], [-350, 350]]
"""


def test_every_preset_has_its_limits() -> None:
    assert set(MOTION_LIMITS) == set(ROBOT_NAMES)
    for name in ROBOT_NAMES:
        limits = motion_limits(name)
        assert limits.name == name and limits.source
        assert motion_limits(get_robot(name)) is limits
    kr6 = motion_limits("KR6-R900")
    assert kr6.joint_speed_deg_s == (360.0, 300.0, 360.0, 381.0, 388.0, 615.0)
    assert motion_limits("ur10e").joint_speed_deg_s[:2] == (120.0, 120.0)
    assert motion_limits("ur5e").speed_mm_s == 1000.0


def test_a_toml_arm_takes_its_own_limits_or_the_nominal_ones(tmp_path) -> None:
    plain = tmp_path / "plain.toml"
    plain.write_text(ARM)
    limits = motion_limits(str(plain))
    assert limits.name == "my-arm" and "nominal where not given" in limits.source
    assert limits.joint_speed_deg_s == NOMINAL.joint_speed_deg_s
    assert limits.speed_mm_s == NOMINAL.speed_mm_s
    fast = tmp_path / "fast.toml"
    fast.write_text(ARM + "speed_mm_s = 1500\njoint_speed_deg_s = [300, 300, 300, 400, 400, 600]\n")
    limits = motion_limits(fast)
    assert limits.speed_mm_s == 1500.0 and limits.joint_speed_deg_s[5] == 600.0
    assert get_robot(fast).name == "my-arm"  # the kinematics read the same file


@pytest.mark.parametrize(
    ("extra", "field"),
    [("speed_mm_s = 0\n", "speed_mm_s"), ("joint_speed_deg_s = [1, 2]\n", "joint_speed_deg_s")],
)
def test_bad_limits_in_a_toml_arm_are_one_line(tmp_path, extra, field) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(ARM + extra)
    with pytest.raises(ValueError) as info:
        motion_limits(path)
    assert "\n" not in str(info.value) and field in str(info.value)
    with pytest.raises(ValueError, match="unknown robot"):
        motion_limits("kr16")


def test_a_robot_file_that_is_not_a_file_is_said_so(tmp_path) -> None:
    fifo, folder, big = tmp_path / "fifo.toml", tmp_path / "folder.toml", tmp_path / "big.toml"
    os.mkfifo(fifo)
    folder.mkdir()
    big.write_text(ARM + "#" * 1024**2)
    for read in (get_robot, motion_limits):  # the FIFO refused, not waited on
        with pytest.raises(ValueError, match=f"^robot file {fifo} is a FIFO .named pipe., not"):
            read(str(fifo))
        with pytest.raises(ValueError, match=f"^robot file {folder} is a directory, not a file"):
            read(str(folder))
    with pytest.raises(ValueError, match="is larger than 1 MiB: not a robot's parameters"):
        get_robot(str(big))
    (tmp_path / "arm.toml").write_text(ARM)
    assert get_robot(str(tmp_path / "arm.toml")).name == "my-arm"


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_the_flange_axis_points_out_of_the_flange(name) -> None:
    """Checked against the kinematics: turning joint 6 spins the flange about that axis (the
    flange's origin and the axis stay put), and the last link runs along it to the flange."""
    arm = get_robot(name)
    q = np.random.default_rng(1).uniform(-1.0, 1.0, (20, 6))
    T = arm.forward(q)
    spun = arm.forward(q + np.array([0, 0, 0, 0, 0, 1.0]))
    out = np.einsum("nij,j->ni", T[:, :3, :3], arm.flange_axis)
    assert np.allclose(T[:, :3, 3], spun[:, :3, 3], atol=1e-9)
    assert np.allclose(out, np.einsum("nij,j->ni", spun[:, :3, :3], arm.flange_axis), atol=1e-9)
    ends = arm.link_capsules(q)[0][:, -1]  # the last link: (n, 2, 3) from the wrist
    along = ends[:, 1] - ends[:, 0]
    assert np.allclose(ends[:, 1], T[:, :3, 3], atol=1e-9)
    assert np.allclose(along / np.linalg.norm(along, axis=1)[:, None], out, atol=1e-9)


def test_a_sensor_mounted_across_the_flange_is_said_with_the_straight_tcp() -> None:
    """On a KUKA the flange's x points out of it: `0,0,90,0,0,0` looks across it."""
    sideways = pose_from_xyzabc([0, 0, 90, 0, 0, 0])
    kuka = across_flange("kr6-r900", get_robot("kr6-r900").flange_axis, sideways)
    assert kuka is not None
    assert "90° off" in kuka and "x axis points out" in kuka
    assert kuka.endswith("--tcp 90,0,0,0,90,0")
    straight = pose_from_xyzabc([90, 0, 0, 0, 90, 0])
    assert across_flange("kr6-r900", get_robot("kr6-r900").flange_axis, straight) is None
    assert across_flange("ur5e", get_robot("ur5e").flange_axis, sideways) is None
    tilted = pose_from_xyzabc([0, 0, 90, 0, 30, 0])  # an angled bracket is not across
    assert across_flange("ur5e", get_robot("ur5e").flange_axis, tilted) is None
