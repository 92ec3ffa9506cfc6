"""ABB RAPID: one MoveL per thinned target, fine zones at pass ends, the tool data, SetDO."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.export import export_program
from scanplan.export.common import plan_motion

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
    assert np.all(zones[m.pass_start | m.pass_end | ~m.scanning] == "fine")
    # Each blend a zone of its own radius, rounded down (in 0.01 mm) so the cap still holds.
    radii = dict(re.findall(r"CONST zonedata (\w+) := \[FALSE,([^,]+),", text))
    for z, b in zip(zones, m.blend_mm, strict=True):
        if z != "fine":
            assert b - 0.01 < float(radii[z]) <= b
    assert text.count("SetDO doScan, 1;") == text.count("SetDO doScan, 0;") == 3
    tool = re.search(r"tooldata tSensor := \[TRUE,\[\[([^\]]*)\],\[([^\]]*)\]\]", text)
    assert tool is not None
    np.testing.assert_allclose([float(v) for v in tool.group(1).split(",")], [12, -3, 180])
    q = np.array([float(v) for v in tool.group(2).split(",")])
    R = Rotation.from_quat([*q[1:], q[0]]).as_matrix()
    np.testing.assert_allclose(R, OPTIONS.tcp[:3, :3], atol=1e-8)
