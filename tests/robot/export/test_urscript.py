"""URScript: one movel per pose, blends, speeds, pass markers, the TCP."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.robot.export import export_program
from scanplan.robot.export.common import plan_motion

TRAJ = snake_trajectory()


def test_urscript_structure() -> None:
    text = export_program(TRAJ, "urscript", OPTIONS)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    code = [ln for ln in lines if not ln.startswith("#")]
    assert code[0] == "def scanplan_path():" and code[-2] == "end"
    assert code[-1] == "scanplan_path()"
    # Every target in the part's frame, flown through the feature (the part's pose).
    movel = re.findall(
        r"movel\(pose_trans\(feature, p\[[^\]]*\]\), a=([^,]+), v=([^,]+), r=([^)]+)\)", text
    )
    m = plan_motion(TRAJ, OPTIONS)
    assert len(movel) == len(m.poses) < len(TRAJ)
    feature = re.search(r"feature = p\[([^\]]*)\]", text)
    assert feature is not None
    part = np.array([float(x) for x in feature.group(1).split(",")])
    np.testing.assert_allclose(part[:3], OPTIONS.part_pose[:3, 3] / 1000, atol=1e-9)
    r = np.array([float(x[2]) for x in movel])
    stops = m.pass_start | m.pass_end
    stops[[0, -1]] = True
    assert np.all(r[stops] == 0) and np.all(r[~stops] > 0)
    np.testing.assert_allclose(r, m.blend_mm / 1000, atol=1e-9)
    v = {float(x[1]) for x in movel}
    assert v == {0.1, 0.3}
    assert {float(x[0]) for x in movel} == {1.0}
    assert len(re.findall(r"# pass \d+ start", text)) == 3
    assert len(re.findall(r"# pass \d+ end", text)) == 3
    assert len(re.findall(r"set_standard_digital_out\(0, True\)", text)) == 3
    assert len(re.findall(r"set_standard_digital_out\(0, False\)", text)) == 3
    tcp = re.search(r"set_tcp\(p\[([^\]]*)\]\)", text)
    assert tcp is not None
    vals = np.array([float(x) for x in tcp.group(1).split(",")])
    # The TCP is the laser line at W_d: the sensor moved 400 mm along its beam (z).
    np.testing.assert_allclose(vals[:3], OPTIONS.tool[:3, 3] / 1000, atol=1e-9)
    np.testing.assert_allclose(OPTIONS.tool[:3, 3], OPTIONS.tcp[:3, 3] + 400 * OPTIONS.tcp[:3, 2])
    R = Rotation.from_rotvec(vals[3:]).as_matrix()
    np.testing.assert_allclose(R, OPTIONS.tcp[:3, :3], atol=1e-8)


def test_urscript_scan_output_option() -> None:
    text = export_program(TRAJ, "urscript", replace(OPTIONS, scan_output="3"))
    assert text.count("set_standard_digital_out(3, True)") == 3
    for bad in ("8", "-1", "doScan"):
        with pytest.raises(ValueError, match="digital output number 0-7"):
            export_program(TRAJ, "urscript", replace(OPTIONS, scan_output=bad))
