"""Every robot-program dialect parsed back and compared with the trajectory it came from;
an unknown format or a bad option is one clear error."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import rot_err, snake_trajectory
from scanplan.export import (
    FORMATS,
    ExportOptions,
    export_program,
    parse_program,
    parse_program_details,
)
from scanplan.export.common import plan_motion
from scanplan.quantities import ScanSpec

TRAJ = snake_trajectory()


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_round_trip(fmt: str) -> None:
    text = export_program(TRAJ, fmt, OPTIONS)
    poses, scanning = parse_program(text, fmt)
    motion = plan_motion(TRAJ, OPTIONS)
    assert motion.n_planned == len(TRAJ) and len(motion.poses) < len(TRAJ) / 4
    # The program holds the thinned targets: planned poses, in the base frame.
    expected = OPTIONS.part_pose @ TRAJ.poses[motion.source]
    assert poses.shape == expected.shape
    assert np.abs(poses[:, :3, 3] - expected[:, :3, 3]).max() < 1e-3  # 1e-6 m
    assert rot_err(poses, expected).max() < 1e-6
    np.testing.assert_array_equal(scanning, TRAJ.scanning[motion.source])

    details = parse_program_details(text, fmt)
    np.testing.assert_allclose(details.speed_mm_s, motion.speed_mm_s, rtol=1e-5)
    if details.blended is not None:
        np.testing.assert_array_equal(details.blended, motion.blend_mm > 0)


def test_bad_options_and_format() -> None:
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(ValueError, match="part pose"):
        ExportOptions(part_pose=skew)
    with pytest.raises(ValueError, match="program name"):
        ExportOptions(program_name="1 bad")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="chord_tol_mm"):
            ExportOptions(chord_tol_mm=bad)
        with pytest.raises(ValueError, match="angle_tol_deg"):
            ExportOptions(angle_tol_deg=bad)
    with pytest.raises(ValueError, match="travel_speed_mm_s"):
        ExportOptions(scan=ScanSpec(travel_speed_mm_s=0))
    with pytest.raises(ValueError, match="unknown export format"):
        export_program(TRAJ, "gcode", OPTIONS)
    with pytest.raises(ValueError, match="no movel"):
        parse_program("def x():\nend\n", "urscript")
