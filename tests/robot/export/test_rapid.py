"""ABB RAPID: one MoveL per thinned target, fine zones at pass ends, the tool data, SetDO."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.core.trajectory import Trajectory
from scanplan.robot import get_robot
from scanplan.robot.export import export_program
from scanplan.robot.export.common import plan_motion
from scanplan.robot.export.rapid import confdata

TRAJ = snake_trajectory()


def test_rapid_structure() -> None:
    text = export_program(TRAJ, "rapid", OPTIONS)
    assert text.startswith("MODULE scanplan_path") and text.rstrip().endswith("ENDMODULE")
    assert "PROC main()" in text and "ENDPROC" in text
    # Every target in the part's work object, whose user frame is the part pose.
    moves = re.findall(r"MoveL (\w+), (\w+), (\w+), tSensor\\WObj:=wobjPart;", text)
    wobj = re.search(r"PERS wobjdata wobjPart := \[FALSE,TRUE,\"\",\[\[([^\]]*)\]", text)
    assert wobj is not None
    np.testing.assert_allclose(
        [float(v) for v in wobj.group(1).split(",")], OPTIONS.part_pose[:3, 3], atol=1e-6
    )
    m = plan_motion(TRAJ, OPTIONS)
    assert len(moves) == len(m.poses) < len(TRAJ)
    zones = np.array([z for _, _, z in moves])
    stops = m.pass_start | m.pass_end
    stops[[0, -1]] = True
    assert np.all(zones[stops] == "fine") and np.all(zones[~stops] != "fine")
    # Each blend a zone of its own radius, rounded down (in 0.01 mm) so the cap still holds.
    radii = dict(re.findall(r"CONST zonedata (\w+) := \[FALSE,([^,]+),", text))
    for z, b in zip(zones, m.blend_mm, strict=True):
        if z != "fine":
            assert b - 0.01 < float(radii[z]) <= b
    assert text.count("SetDO doScan, 1;") == text.count("SetDO doScan, 0;") == 3
    tool = re.search(r"tooldata tSensor := \[TRUE,\[\[([^\]]*)\],\[([^\]]*)\]\]", text)
    assert tool is not None
    # The tool is where the laser line meets the part: T_flange_sensor moved W_d along z.
    xyz = [float(v) for v in tool.group(1).split(",")]
    np.testing.assert_allclose(xyz, OPTIONS.tool[:3, 3], atol=1e-6)
    np.testing.assert_allclose(OPTIONS.tool[:3, 3], [12, -3, 180] + 400 * OPTIONS.tcp[:3, 2])
    q = np.array([float(v) for v in tool.group(2).split(",")])
    R = Rotation.from_quat([*q[1:], q[0]]).as_matrix()
    np.testing.assert_allclose(R, OPTIONS.tcp[:3, :3], atol=1e-8)


def test_rapid_confdata_is_the_chosen_configuration() -> None:
    arm = get_robot("irb2400")
    q = np.radians([100.0, 10.0, -20.0, -95.0, -40.0, 200.0])
    # Quadrants of axes 1, 4, 6; cfx 1: wrist centre in front of axis 1 and the lower arm,
    # axis 5 negative.
    np.testing.assert_array_equal(confdata(q[None], arm), [[1, -2, 2, 1]])
    branches = arm.inverse(arm.forward(q)[None])[0]
    assert np.isfinite(branches).all()
    assert sorted(confdata(branches, arm)[:, 3]) == list(range(8))
    poses = np.tile(np.linalg.inv(OPTIONS.part_pose) @ arm.forward(q) @ OPTIONS.tcp, (3, 1, 1))
    poses[:, 0, 3] += [0.0, 5.0, 10.0]
    options = replace(OPTIONS, joints_rad=np.tile(q, (3, 1)), arm=arm)
    text = export_program(Trajectory(poses, [0] * 3, [True] * 3), "rapid", options)
    assert text.count(",[1,-2,2,1],[9E+09") == 2  # one straight move: its ends
    assert "MoveAbsJ [[100.0000,10.0000,-20.0000,-95.0000,-40.0000,200.0000]" in text
    with pytest.raises(ValueError, match="signal name"):
        export_program(TRAJ, "rapid", replace(OPTIONS, scan_output="7"))
