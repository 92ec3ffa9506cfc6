"""UR kinematics answers: known poses, FK/IK round trips, singularities, reachability."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scanplan.robot import (
    UR_MODELS,
    check_reach,
    forward_kinematics,
    inverse_kinematics,
    singularity_margins,
)


def test_zero_pose_matches_published_home() -> None:
    # UR5e at all-zero joints: flange at (a2 + a3, -(d4 + d6), d1 - d5).
    T = forward_kinematics(np.zeros(6), "ur5e")
    np.testing.assert_allclose(T[:3, 3], [-817.2, -232.9, 62.8], atol=1e-9)


@pytest.mark.parametrize("model", list(UR_MODELS))
def test_fk_ik_round_trip(model: str) -> None:
    q = np.random.default_rng(7).uniform(-np.pi, np.pi, (300, 6))
    T = forward_kinematics(q, model)
    solutions = inverse_kinematics(T, model)
    assert solutions.shape == (300, 8, 6)
    valid = ~np.isnan(solutions).any(axis=2)
    T_back = forward_kinematics(np.where(valid[..., None], solutions, 0.0), model)
    err = np.abs(T_back - T[:, None]).max(axis=(2, 3))
    assert err[valid].max() < 1e-6  # every solution reproduces the pose (mm)
    # ... and the joint vector we started from is one of them.
    dq = np.abs(np.angle(np.exp(1j * (solutions - q[:, None])))).max(axis=2)
    assert np.all(np.nanmin(dq, axis=1) < 1e-6)


def _numeric_jacobian(q: np.ndarray, model: str) -> np.ndarray:
    T = forward_kinematics(q, model)
    J = np.zeros((6, 6))
    h = 1e-6
    for j in range(6):
        T2 = forward_kinematics(q + h * np.eye(6)[j], model)
        J[:3, j] = (T2[:3, 3] - T[:3, 3]) / h
        J[3:, j] = Rotation.from_matrix(T2[:3, :3] @ T[:3, :3].T).as_rotvec() / h
    return J


def test_margins_are_the_jacobian_factors() -> None:
    # |det J| = |a2 a3| · |sin q5| · |sin q3| · shoulder: the three margins are exactly
    # the singularities, none missed.
    m = UR_MODELS["ur5e"]
    for q in np.random.default_rng(3).uniform(-3, 3, (5, 6)):
        det = abs(np.linalg.det(_numeric_jacobian(q, "ur5e")))
        assert det == pytest.approx(abs(m.a2 * m.a3) * singularity_margins(q).prod(), rel=1e-4)


def test_unreachable_poses() -> None:
    far = np.eye(4)
    far[:3, 3] = [2000.0, 0.0, 300.0]
    # Wrist centre on the joint-1 axis: closer than d4, no shoulder solution.
    axis = np.eye(4)
    axis[:3, 3] = [0.0, 0.0, 400.0 + UR_MODELS["ur5e"].d6]
    ok = forward_kinematics([0.3, -1.2, 1.5, -1.9, 1.2, 0.4])
    report = check_reach(np.stack([ok, far, axis]), "ur5e")
    np.testing.assert_array_equal(report.unreachable, [1, 2])
    assert np.isnan(report.joints[1]).all() and not np.isnan(report.joints[0]).any()
    assert "2 unreachable" in report.summary()
    assert not report.ok


def test_singular_poses_flagged() -> None:
    m = UR_MODELS["ur5e"]
    q2 = np.arctan2(-m.a2, m.a3)  # a2 cos q2 + a3 sin q2 = 0 with q3 = -90°, s234 = 0
    configs = np.array(
        [
            [0.3, -1.2, 1.5, -1.9, 1.2, 0.4],  # regular
            [0.3, -1.2, 1.5, -1.9, 0.0, 0.4],  # wrist: axes 4 and 6 aligned
            [0.3, -1.2, 0.0, -1.9, 1.2, 0.4],  # elbow: arm stretched
            [0.3, q2, -np.pi / 2, np.pi / 2 - q2, 1.2, 0.4],  # shoulder
        ]
    )
    det = [abs(np.linalg.det(_numeric_jacobian(q, "ur5e"))) for q in configs]
    assert max(det[1:]) < 1e-6 * det[0]
    report = check_reach(forward_kinematics(configs), "ur5e", q_start=configs[0])
    assert len(report.unreachable) == 0
    assert 1 in report.wrist_singular and 2 in report.elbow_singular
    assert 3 in report.shoulder_singular and 0 not in report.near_singular


def test_follows_a_smooth_path_and_reports_wrist_flip() -> None:
    # A joint path whose q5 crosses 0: the closest-solution branch must track it exactly,
    # with no jump, one wrist flip where sin q5 changes sign, and singular poses around it.
    s = np.linspace(0, 1, 200)[:, None]
    q0 = np.array([0.3, -1.4, 1.6, -1.7, 0.35, 0.4])
    q1 = np.array([0.5, -1.2, 1.4, -1.5, -0.35, 0.2])
    q = q0 + s * (q1 - q0)
    report = check_reach(forward_kinematics(q), "ur5e", q_start=q0)
    np.testing.assert_allclose(report.joints, q, atol=1e-8)
    assert len(report.joint_jumps) == 0
    np.testing.assert_array_equal(report.wrist_flips, [100])  # q5 crosses 0 between 99 and 100
    assert {99, 100} <= set(report.wrist_singular) and 0 not in report.wrist_singular


def test_tool_spin_is_a_joint_jump() -> None:
    q = np.array([0.3, -1.2, 1.5, -1.9, 1.2, 0.4])
    T = forward_kinematics(q)
    spun = T.copy()
    spun[:3, :3] = T[:3, :3] @ Rotation.from_euler("z", 180, degrees=True).as_matrix()
    report = check_reach(np.stack([T, spun]), "ur5e", q_start=q)
    np.testing.assert_array_equal(report.joint_jumps, [1])
    assert report.joints[1, 5] == pytest.approx(q[5] + np.pi) or report.joints[
        1, 5
    ] == pytest.approx(q[5] - np.pi)


def test_tied_branches_are_not_told_apart_by_a_poses_last_digits():
    # A UR5e pose (the first of a featuretype plan) where four branches tie on their joint
    # limit margin: read back from a file, its last digits must not pick another branch.
    pose = np.array(
        [
            [0.1507777329615, -0.9885676887513, 0.0, -156.3138252473],
            [-0.9885676887513, -0.1507777329615, 0.0, 210.4715993407],
            [0.0, 0.0, -1.0, 375.593151],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    rng = np.random.default_rng(0)
    first = check_reach(pose[None], "ur5e").joints[0]
    for _ in range(20):
        nudged = pose.copy()
        nudged[:3, 3] += rng.uniform(-5e-7, 5e-7, 3)
        assert np.allclose(check_reach(nudged[None], "ur5e").joints[0], first, atol=1e-5)
