"""KUKA KRL: one LIN per thinned target, blends, the tool, intrinsic ZYX angles, the
acquisition output, PTP into each pass with Status and Turn."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from helpers import EXPORT_OPTIONS as OPTIONS
from helpers import snake_trajectory
from scanplan.export import (
    ExportOptions,
    export_program,
)
from scanplan.export.common import plan_motion
from scanplan.trajectory import Trajectory

TRAJ = snake_trajectory()


def test_krl_structure() -> None:
    text = export_program(TRAJ, "krl", OPTIONS)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    assert "DEF scanplan_path( )" in lines and lines[-1] == "END"
    lins = [ln for ln in lines if ln.startswith("LIN ")]
    m = plan_motion(TRAJ, OPTIONS)
    assert len(lins) == len(m.poses) < len(TRAJ)
    # The targets are in the part's frame, $BASE the part's pose in the base frame.
    base = next(ln for ln in lines if ln.startswith("$BASE = "))
    assert base.startswith("$BASE = {X 500.000000,Y -200.000000,Z 100.000000,A 30.0")
    first = [float(v.split()[1]) for v in lins[0][5:-1].split(",")[:3]]
    np.testing.assert_allclose(first, TRAJ.poses[0, :3, 3], atol=1e-5)
    blended = np.array([ln.endswith("C_DIS") for ln in lins])
    np.testing.assert_array_equal(blended, m.blend_mm > 0)
    assert not blended[m.pass_start | m.pass_end].any()
    assert (
        "$TOOL = {X 12.000000,Y -3.000000,Z 180.000000,A 0.000000,B -15.000000,C 90.000000}"
        in lines
    )
    assert {ln for ln in lines if ln.startswith("$VEL.CP")} == {"$VEL.CP = 0.1", "$VEL.CP = 0.3"}
    # Acquisition on right after each pass's first target, off right after its last.
    on = [i for i, ln in enumerate(lines) if ln.startswith("$OUT[1] = TRUE")]
    off = [i for i, ln in enumerate(lines) if ln.startswith("$OUT[1] = FALSE")]
    assert len(on) == len(off) == 3
    starts, ends = np.flatnonzero(m.pass_start), np.flatnonzero(m.pass_end)
    assert [lines[i - 1] for i in on] == [lins[j] for j in starts]
    assert [lines[i - 1] for i in off] == [lins[j] for j in ends]


def test_krl_angles_are_intrinsic_zyx() -> None:
    T = np.eye(4)
    T[:3, :3] = (
        Rotation.from_euler("z", 30, degrees=True)
        * Rotation.from_euler("y", 20, degrees=True)
        * Rotation.from_euler("x", 10, degrees=True)
    ).as_matrix()
    text = export_program(Trajectory(T[None], [0], [True]), "krl", ExportOptions())
    assert "LIN {X 0.000000,Y 0.000000,Z 0.000000,A 30.000000,B 20.000000,C 10.000000}" in text
