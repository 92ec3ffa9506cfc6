"""Where a program moves by joint (its first target, where each pass is entered, where the
turntable turns) and into which joints, and how fast a dialect makes those moves.
"""

from __future__ import annotations

import numpy as np

from scanplan.robot.export.common import ExportOptions, Motion

# Joint moves into a pass's configuration: a moderate share of any arm's axis speed.
JOINT_SPEED_DEG_S = 60.0
JOINT_ACCEL_DEG_S2 = 120.0


def target_joints(motion: Motion, options: ExportOptions) -> np.ndarray | None:
    """(n, 6) the arm's joint angles at each target (rad), None when the options carry none."""
    if options.joints_rad is None:
        return None
    joints = np.asarray(options.joints_rad, dtype=np.float64)
    if joints.shape != (motion.n_planned, 6):
        raise ValueError(f"joints must be ({motion.n_planned}, 6), got {joints.shape}")
    return joints[motion.source]


def joint_move_targets(motion: Motion, options: ExportOptions) -> dict[int, np.ndarray]:
    """{target index: joint angles (6,) rad} where the program moves by joint: its first
    target and where every pass is entered (`Motion.entry`), when the options carry the
    arm's joints."""
    joints = target_joints(motion, options)
    if joints is None:
        return {}
    step = np.zeros(len(motion.poses), bool) if motion.axis_step is None else motion.axis_step
    entry = motion.pass_start if motion.entry is None else motion.entry
    where = np.flatnonzero(entry | step | (np.arange(len(motion.poses)) == 0))
    return {int(i): joints[i] for i in where if np.isfinite(joints[i]).all()}


__all__ = ["JOINT_ACCEL_DEG_S2", "JOINT_SPEED_DEG_S", "joint_move_targets", "target_joints"]
