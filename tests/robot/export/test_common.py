"""What every dialect shares (export.common): the motion rules, flange poses, pose arguments."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.core.limits import TCP_MM
from scanplan.robot.export import (
    flange_poses,
    parse_pose_arg,
)
from scanplan.robot.export.common import plan_motion

TRAJ = snake_trajectory()


def test_motion_rules() -> None:
    m = plan_motion(TRAJ, OPTIONS)
    runs = int(m.pass_start.sum())
    assert runs == 3 == int(m.pass_end.sum())
    ends = m.pass_start | m.pass_end
    ends[[0, -1]] = True
    assert np.all(m.blend_mm[ends] == 0)
    # 0.5 mm between stations: blends capped at half a segment so neighbours never overlap.
    inner = m.blend_mm[~ends & m.scanning]
    assert inner.max() <= 0.2 + 1e-12 and inner.min() > 0
    # The lifted transitions between passes are blended too, beyond the scanning cap.
    moves = m.blend_mm[~ends & ~m.scanning]
    assert len(moves) == 4 and moves.min() > 0.2
    assert np.all(m.speed_mm_s[m.scanning & ~m.pass_start] == 100.0)  # 200 Hz · 0.5 mm
    assert np.all(m.speed_mm_s[~m.scanning | m.pass_start] == 300.0)


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


def test_parse_pose_arg_holds_magnitudes_to_their_ranges() -> None:
    with pytest.raises(ValueError, match=r"y 1e\+308 is not in \[-100000, 100000\] mm"):
        parse_pose_arg("0,1e308,0,0,0,0")
    with pytest.raises(ValueError, match=r"C -400 is not in \[-360, 360\] deg"):
        parse_pose_arg("0,0,0,0,0,-400")
    with pytest.raises(ValueError, match=r"x 6000 is not in \[-5000, 5000\] mm"):
        parse_pose_arg("6000,0,0,0,0,0", TCP_MM)
    with pytest.raises(ValueError, match=r"pose '1{77}\.\.\.': expected 6"):
        parse_pose_arg("1" * 400)
    np.testing.assert_allclose(parse_pose_arg("1e5,0,0,360,0,0")[:3, 3], [1e5, 0, 0])
