"""OPW kinematics answers: round trips, all eight branches, published frames, user files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scanplan.robot import OPW_PRESETS, ROBOT_NAMES, check_reach, get_robot, load_robot_file
from scanplan.robot.nearest_joints import fit_limits

PRESETS = list(ROBOT_NAMES)


def _random_q(robot, n: int, seed: int) -> np.ndarray:
    lim = np.clip(robot.joint_limits, -np.pi, np.pi)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, 6))


@pytest.mark.parametrize("name", PRESETS)
def test_forward_of_every_inverse_branch_is_the_pose(name: str) -> None:
    robot = get_robot(name)
    q = _random_q(robot, 500, 11)
    T = robot.forward(q)
    solutions = robot.inverse(T)
    assert solutions.shape == (500, 8, 6)
    valid = ~np.isnan(solutions).any(axis=2)
    T_back = robot.forward(np.where(valid[..., None], solutions, 0.0))
    pos_err = np.abs(T_back[..., :3, 3] - T[:, None, :3, 3]).max(axis=2)
    rot_err = np.abs(T_back[..., :3, :3] - T[:, None, :3, :3]).max(axis=(2, 3))
    assert pos_err[valid].max() < 1e-6  # mm: 1e-9 m
    assert rot_err[valid].max() < 1e-9
    # The joint vector we started from is one of the branches (modulo 2π).
    dq = np.abs(np.angle(np.exp(1j * (solutions - q[:, None])))).max(axis=2)
    assert np.nanmin(dq, axis=1).max() < 1e-7


@pytest.mark.parametrize("name", PRESETS)
def test_generic_poses_have_eight_distinct_branches(name: str) -> None:
    # Wherever the wrist centre is within reach of both shoulder sides (generic poses off
    # the singularities), all eight branches exist and differ: every one is found.
    robot = get_robot(name)
    q = _random_q(robot, 400, 4)
    margins = np.abs(robot.singularity_terms(q)).min(axis=1)
    solutions = robot.inverse(robot.forward(q[margins > 0.05]))
    full = ~np.isnan(solutions).any(axis=(1, 2))
    assert full.mean() > 0.2
    s = solutions[full]
    d = np.abs(np.angle(np.exp(1j * (s[:, :, None] - s[:, None])))).max(axis=3)
    assert (d + np.eye(8) * 10).min() > 1e-3
    # Where a branch is missing, its whole shoulder side is out of reach, never one branch.
    missing = np.isnan(solutions[~full]).any(axis=2)
    assert (missing.sum(axis=1) % 2 == 0).all()


def _urdf_chain(origins_mm, axes, tip_rpy, q) -> np.ndarray:
    """FK of a ROS-Industrial URDF: per joint a translation then a rotation about its axis."""
    T = np.eye(4)
    for o, a, qi in zip(origins_mm, axes, q, strict=True):
        J = np.eye(4)
        J[:3, 3] = o
        J[:3, :3] = Rotation.from_rotvec(np.asarray(a, float) * qi).as_matrix()
        T = T @ J
    F = np.eye(4)
    F[:3, :3] = Rotation.from_euler("xyz", tip_rpy).as_matrix()
    return T @ F


# Joint origins (mm) and axes of ROS-Industrial's URDFs (kuka_experimental
# kr6r900sixx_macro.xacro, abb irb2400_macro.xacro, fanuc lrmate200id_macro.xacro), and the
# fixed rotation from link_6 to the controller's flange frame: KUKA $FLANGE = link_6,
# ABB tool0 = link_6 · Ry(90°), Fanuc faceplate = tool0 = link_6 · rpy(180°, -90°, 0).
URDF = {
    "kr6-r900": (
        [(0, 0, 400), (25, 0, 0), (455, 0, 0), (0, 0, 35), (420, 0, 0), (80, 0, 0)],
        [(0, 0, -1), (0, 1, 0), (0, 1, 0), (-1, 0, 0), (0, 1, 0), (-1, 0, 0)],
        (0, 0, 0),
        np.zeros(3),
    ),
    "irb2400": (
        [(0, 0, 0), (100, 0, 615), (0, 0, 705), (258, 0, 135), (497, 0, 0), (85, 0, 0)],
        [(0, 0, 1), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0)],
        (0, np.pi / 2, 0),
        np.zeros(3),
    ),
    "lrmate200id": (
        [(0, 0, 330), (50, 0, 0), (0, 0, 330), (0, 0, 35), (335, 0, 0), (80, 0, 0)],
        [(0, 0, 1), (0, 1, 0), (0, -1, 0), (-1, 0, 0), (0, -1, 0), (-1, 0, 0)],
        (np.pi, -np.pi / 2, 0),
        np.array([0, 0, 330.0]),  # Fanuc World is 330 mm above base_link
    ),
}


@pytest.mark.parametrize("name", list(URDF))
def test_matches_the_published_urdf_chain(name: str) -> None:
    origins, axes, tip, world = URDF[name]
    robot = OPW_PRESETS[name]
    for q in _random_q(robot, 20, 5):
        q_urdf = q.copy()
        if robot.j3_from_horizontal:
            q_urdf[2] = q[2] + q[1]  # Fanuc J3 is the forearm's angle from the horizontal
        expected = _urdf_chain(origins, axes, tip, q_urdf)
        expected[:3, 3] -= world
        np.testing.assert_allclose(robot.forward(q), expected, atol=1e-9)


@pytest.mark.parametrize(
    ("name", "flange_mm", "z_axis"),
    [
        # KR 6 R900 sixx at A1..A6 = 0: arm stretched forward, A2 = 0 horizontal upper arm:
        # x = 25 + 455 + 420 + 80 = 980, z = 400 + 35 (KUKA dimension drawing); $FLANGE
        # is then aligned with the base (X out of the flange, forward), so Z is up.
        ("kr6-r900", [980.0, 0.0, 435.0], [0, 0, 1]),
        # IRB 2400 at the calibration position: tool0 at x = 100 + 755 + 85 = 940,
        # z = 615 + 705 + 135 = 1455 (ABB product specification drawing), Z forward.
        ("irb2400", [940.0, 0.0, 1455.0], [1, 0, 0]),
        # LR Mate 200iD at zero in Fanuc World (J2 height): x = 50 + 335 + 80 = 465,
        # z = 330 + 35 = 365 (FANUC data sheet drawing: 330 / 335 / 80 mm, J3 offset 35).
        ("lrmate200id", [465.0, 0.0, 365.0], [1, 0, 0]),
    ],
)
def test_zero_pose_is_the_manufacturers_drawing(name, flange_mm, z_axis) -> None:
    T = get_robot(name).forward(np.zeros(6))
    np.testing.assert_allclose(T[:3, 3], flange_mm, atol=1e-9)
    np.testing.assert_allclose(T[:3, 2], z_axis, atol=1e-12)


def _numeric_jacobian(robot, q: np.ndarray) -> np.ndarray:
    T = robot.forward(q)
    J = np.zeros((6, 6))
    h = 1e-6
    for j in range(6):
        T2 = robot.forward(q + h * np.eye(6)[j])
        J[:3, j] = (T2[:3, 3] - T[:3, 3]) / h
        J[3:, j] = Rotation.from_matrix(T2[:3, :3] @ T[:3, :3].T).as_rotvec() / h
    return J


@pytest.mark.parametrize("name", list(OPW_PRESETS))
def test_margins_are_the_jacobian_factors(name: str) -> None:
    r = OPW_PRESETS[name]
    k = np.hypot(r.a2, r.c3)
    for q in _random_q(r, 5, 3):
        det = abs(np.linalg.det(_numeric_jacobian(r, q)))
        margins = np.abs(r.singularity_terms(q)).prod()
        assert det == pytest.approx(r.c2 * k * margins, rel=1e-4)


def test_joint_limits_are_enforced() -> None:
    # Poses made with A3 folded beyond its -120° limit: those no in-limit branch reaches
    # are limit violations (reachable geometrically, not by this arm), the rest are fine.
    kr6 = get_robot("kr6-r900")
    q = _random_q(kr6, 200, 9)
    q[:100, 2] = np.radians(-150.0)
    T = kr6.forward(q)
    _, inside = fit_limits(kr6.inverse(T), kr6.joint_limits)
    report = check_reach(T, kr6, jump_deg=360)
    assert len(report.unreachable) == 0
    np.testing.assert_array_equal(report.limit_violations, np.flatnonzero(~inside.any(axis=1)))
    assert len(report.limit_violations) > 50 and report.limit_violations.max() < 100
    assert not report.reachable
    ok = ~np.isnan(report.joints).any(axis=1)
    lim = kr6.joint_limits
    assert ((report.joints[ok] >= lim[:, 0]) & (report.joints[ok] <= lim[:, 1])).all()
    assert (report.limit_margin_rad[ok] >= 0).all()


GOOD = """
name = "kr6-copy"
a1 = 25
a2 = -35
c1 = 400
c2 = 455
c3 = 420
c4 = 80
offsets_deg = [0, -90, 0, 0, 0, 0]
sign = [-1, 1, 1, -1, 1, -1]
limits_deg = [[-170, 170], [-190, 45], [-120, 156], [-185, 185], [-120, 120], [-350, 350]]
flange = [0, 0, 0, 0, -90, 0]
"""


def test_user_toml_equals_the_preset(tmp_path) -> None:
    path = tmp_path / "arm.toml"
    path.write_text(GOOD)
    arm = get_robot(str(path))
    preset = get_robot("kr6-r900")
    q = _random_q(preset, 50, 2)
    np.testing.assert_allclose(arm.forward(q), preset.forward(q), atol=1e-9)
    np.testing.assert_allclose(arm.joint_limits, preset.joint_limits)
    assert arm.name == "kr6-copy"


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda s: s.replace("c2 = 455", "c2 = -455"), "c2"),
        (lambda s: s.replace("sign = [-1, 1, 1, -1, 1, -1]", "sign = [2, 1, 1, 1, 1, 1]"), "sign"),
        (lambda s: s.replace("[-190, 45]", "[45, -190]"), "limits_deg"),
        (lambda s: s.replace("[-350, 350]]", "]"), "limits_deg"),
        (lambda s: s.replace("c1 = 400", "c1 = 'high'"), "c1"),
        (lambda s: s + "\nspeed = 3\n", "speed"),
        (lambda s: s.replace("c3 = 420\n", ""), "c3"),
        (lambda s: s.replace("a1 = 25", "a1 = = 25"), "cannot be parsed"),
        (lambda s: s.replace("c4 = 80", "c4 = nan"), "c4"),
        # Issue 26: lengths an arm could have, not infinities, 1e308 or denormals.
        (lambda s: s.replace("c2 = 455", "c2 = inf"), "c2"),
        (lambda s: s.replace("c2 = 455", "c2 = 1e-300"), "c2"),
        (lambda s: s.replace("a1 = 25", "a1 = 1e308"), "a1"),
        (lambda s: s.replace("c3 = 420", "c3 = -1e308"), "c3"),
    ],
)
def test_bad_user_toml_is_one_line_naming_the_field(tmp_path, edit, field) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(edit(GOOD))
    with pytest.raises(ValueError) as info:
        load_robot_file(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and field in message


def test_unknown_robot_lists_the_choices(tmp_path) -> None:
    with pytest.raises(ValueError, match="kr6-r900.*irb2400.*lrmate200id"):
        get_robot("kr16")
    with pytest.raises(ValueError, match="does not exist"):
        get_robot(str(tmp_path / "none.toml"))
