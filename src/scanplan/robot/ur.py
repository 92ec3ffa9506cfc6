"""Universal Robots e-Series kinematics (UR3e, UR5e, UR10e).

Standard DH parameters as published by Universal Robots ("Parameters for calculations of
kinematics and dynamics"), in mm. Frame 0 is the controller's base frame and frame 6 the
tool flange, so poses here are `T_base_flange` as the teach pendant shows them (not ROS
`base_link`, which is turned 180° about Z). The inverse kinematics is the closed form of
Hawkins (2013): up to 8 solutions, shoulder left/right × wrist up/down × elbow up/down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanplan.robot.base import acos_or_nan as _acos_or_nan
from scanplan.robot.base import as_poses
from scanplan.robot.base import wrap as _wrap


@dataclass(frozen=True)
class URModel:
    name: str
    d1: float
    a2: float
    a3: float
    d4: float
    d5: float
    d6: float
    # Working range per joint, degrees (e-Series datasheets: ±360° on every joint; the
    # UR3e's wrist 3 turns without limit).
    range_deg: tuple[float, ...] = (360.0,) * 6

    @property
    def joint_limits(self) -> np.ndarray:
        r = np.radians(np.asarray(self.range_deg, dtype=np.float64))
        return np.stack([-r, r], axis=1)

    def forward(self, q: np.ndarray) -> np.ndarray:
        return forward_kinematics(q, self)

    def inverse(self, T_base_flange: np.ndarray) -> np.ndarray:
        return inverse_kinematics(T_base_flange, self)

    def singularity_terms(self, q: np.ndarray) -> np.ndarray:
        return _singularity_terms(q, self)

    @property
    def flange_axis(self) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    def link_capsules(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        return _link_capsules(q, self)

    @property
    def dh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(a, d, alpha) per joint, mm and rad."""
        a = np.array([0.0, self.a2, self.a3, 0.0, 0.0, 0.0])
        d = np.array([self.d1, 0.0, 0.0, self.d4, self.d5, self.d6])
        alpha = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])
        return a, d, alpha


UR_MODELS: dict[str, URModel] = {
    "ur3e": URModel("ur3e", 151.85, -243.55, -213.2, 131.05, 85.35, 92.1, (360.0,) * 5 + (np.inf,)),
    "ur5e": URModel("ur5e", 162.5, -425.0, -392.2, 133.3, 99.7, 99.6),
    "ur10e": URModel("ur10e", 180.7, -612.7, -571.55, 174.15, 119.85, 116.55),
}


def get_model(model: str | URModel) -> URModel:
    if isinstance(model, URModel):
        return model
    try:
        return UR_MODELS[model.lower()]
    except KeyError:
        raise ValueError(f"unknown robot {model!r}; choose one of {', '.join(UR_MODELS)}") from None


def _dh(theta: np.ndarray, d: float, a: float, alpha: float) -> np.ndarray:
    """(…, 4, 4) Rz(θ) Tz(d) Tx(a) Rx(α)."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros((*np.shape(theta), 4, 4))
    T[..., 0, :] = np.stack([ct, -st * ca, st * sa, a * ct], axis=-1)
    T[..., 1, :] = np.stack([st, ct * ca, -ct * sa, a * st], axis=-1)
    T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = sa, ca, d
    T[..., 3, 3] = 1.0
    return T


def forward_kinematics(q: np.ndarray, model: str | URModel = "ur5e") -> np.ndarray:
    """(…, 4, 4) `T_base_flange` in mm from joint angles q (…, 6) in rad."""
    a, d, alpha = get_model(model).dh
    q = np.asarray(q, dtype=np.float64)
    T = _dh(q[..., 0], d[0], a[0], alpha[0])
    for j in range(1, 6):
        T = T @ _dh(q[..., j], d[j], a[j], alpha[j])
    return T


def inverse_kinematics(T_base_flange: np.ndarray, model: str | URModel = "ur5e") -> np.ndarray:
    """(n, 8, 6) joint solutions in (-π, π] for (n, 4, 4) flange poses in mm; NaN rows where
    a branch does not exist. Order: index = 4·shoulder + 2·wrist + elbow."""
    m = get_model(model)
    T06 = as_poses(T_base_flange)
    n = len(T06)
    # θ1: the wrist centre p05 must lie at distance d4 from the plane of the arm.
    p05 = T06[:, :3, 3] - m.d6 * T06[:, :3, 2]
    r = np.hypot(p05[:, 0], p05[:, 1])
    psi = np.arctan2(p05[:, 1], p05[:, 0])
    phi = np.arcsin(np.clip(m.d4 / np.maximum(r, 1e-12), -1.0, 1.0))
    phi = np.where(r >= m.d4 * (1 - 1e-12), phi, np.nan)
    t1 = np.stack([psi + phi, psi + np.pi - phi], axis=1)  # (n, 2)
    s1, c1 = np.sin(t1), np.cos(t1)
    # θ5: height of the flange above that plane.
    p = T06[:, None, :3, 3]
    c5 = (p[..., 0] * s1 - p[..., 1] * c1 - m.d4) / m.d6
    t5a = _acos_or_nan(c5)
    t5 = np.stack([t5a, -t5a], axis=2)  # (n, 2, 2)
    # T16 = A1(θ1)⁻¹ T06, written out (the batched 4x4 products cost two thirds of the
    # call): its rows are c1·row0 + s1·row1, row2 - d1 (translation), s1·row0 - c1·row1.
    R, c1, s1 = T06[:, None, :3], c1[..., None], s1[..., None]  # (n, 1, 3, 4), (n, 2, 1)
    row0 = c1 * R[:, :, 0] + s1 * R[:, :, 1]  # (n, 2, 4)
    row1 = np.broadcast_to(R[:, :, 2], row0.shape).copy()
    row1[..., 3] -= m.d1
    row2 = s1 * R[:, :, 0] - c1 * R[:, :, 1]
    # Its last row's rotation is [s5 c6, -s5 s6, c5] (R16 = Rz(θ234) Ry(-θ5) Rz(θ6)).
    s5 = np.sin(t5)
    sgn = np.where(s5 < 0, -1.0, 1.0)
    singular = np.abs(s5) < 1e-10
    t6 = np.where(singular, 0.0, np.arctan2(-row2[:, :, None, 1] * sgn, row2[:, :, None, 0] * sgn))
    # The remaining three parallel joints form a planar 2-link arm plus a wrist angle:
    # T14 = T16 (A5 A6)⁻¹, whose first column is (c5 c6, -c5 s6, -s5, 0) and last
    # (d5 s6, d5 c6, -d6, 1); rows 0 and 1 of T14 are all that is needed.
    cos5, c6, s6 = np.cos(t5), np.cos(t6), np.sin(t6)
    col0 = (cos5 * c6, -cos5 * s6, -s5)
    col3 = (m.d5 * s6, m.d5 * c6, -m.d6)
    r0, r1 = row0[:, :, None], row1[:, :, None]  # (n, 2, 1, 4)
    x = r0[..., 0] * col3[0] + r0[..., 1] * col3[1] + r0[..., 2] * col3[2] + r0[..., 3]
    y = r1[..., 0] * col3[0] + r1[..., 1] * col3[1] + r1[..., 2] * col3[2] + r1[..., 3]
    t234 = np.arctan2(
        r1[..., 0] * col0[0] + r1[..., 1] * col0[1] + r1[..., 2] * col0[2],
        r0[..., 0] * col0[0] + r0[..., 1] * col0[1] + r0[..., 2] * col0[2],
    )[..., None]
    c3 = (x**2 + y**2 - m.a2**2 - m.a3**2) / (2 * m.a2 * m.a3)
    t3a = _acos_or_nan(c3)
    t3 = np.stack([t3a, -t3a], axis=3)  # (n, 2, 2, 2)
    x, y = x[..., None], y[..., None]
    t2 = np.arctan2(y, x) - np.arctan2(m.a3 * np.sin(t3), m.a2 + m.a3 * np.cos(t3))
    t4 = t234 - t2 - t3
    shape = t3.shape
    # Wrapped before the shared angles are spread over the branches (fewer to wrap).
    q = np.stack(
        [
            np.broadcast_to(_wrap(t1)[:, :, None, None], shape),
            _wrap(t2),
            _wrap(t3),
            _wrap(t4),
            np.broadcast_to(_wrap(t5)[..., None], shape),
            np.broadcast_to(_wrap(t6)[..., None], shape),
        ],
        axis=-1,
    ).reshape(n, 8, 6)
    q[np.isnan(q).any(axis=2)] = np.nan
    return q


def singularity_margins(q: np.ndarray, model: str | URModel = "ur5e") -> np.ndarray:
    """(…, 3) |singularity terms|: see `_singularity_terms`."""
    return np.abs(_singularity_terms(q, get_model(model)))


def _singularity_terms(q: np.ndarray, m: URModel) -> np.ndarray:
    """(…, 3) signed distances from the three UR singularities, whose product is det J up to a
    constant: |sin q5| (wrist: axes 4 and 6 align), |sin q3| (elbow: arm stretched or
    folded), and, in mm, the distance of the wrist centre from the plane through the
    joint-1 axis parallel to axis 2 (shoulder)."""
    q = np.asarray(q, dtype=np.float64)
    q2, q3, q234 = q[..., 1], q[..., 2], q[..., 1] + q[..., 2] + q[..., 3]
    shoulder = m.a2 * np.cos(q2) + m.a3 * np.cos(q2 + q3) + m.d5 * np.sin(q234)
    return np.stack([np.sin(q[..., 4]), np.sin(q3), shoulder], axis=-1)


# UR5e collision capsules (mm) as MuJoCo Menagerie's universal_robots_ur5e model draws them
# (derived from Universal Robots' URDF): the upper arm runs 138 mm along the joint-2 axis
# from the DH line, the forearm 7 mm; the UR3e and UR10e are scaled by their upper arm.
_UR5E_UPPER_ARM_MM = 425.0
_UR5E_OFFSETS_MM = (138.0, 7.0)  # upper arm, forearm: along the joint-2 axis
_UR5E_RADII_MM = (60.0, 60.0, 50.0, 55.0, 40.0, 40.0, 40.0, 40.0)


def _link_capsules(q: np.ndarray, m: URModel) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Capsules on the DH frames: the shoulder column and housing, the upper arm and the
    forearm at their offsets along the parallel axes 2-4, the elbow housing, the three
    wrist links to the flange."""
    a, d, alpha = m.dh
    q = np.asarray(q, dtype=np.float64)
    scale = abs(m.a2) / _UR5E_UPPER_ARM_MM
    o1, o2 = (v * scale for v in _UR5E_OFFSETS_MM)
    frames = [_dh(q[..., 0], d[0], a[0], alpha[0])]
    for j in range(1, 6):
        frames.append(frames[-1] @ _dh(q[..., j], d[j], a[j], alpha[j]))
    p = [f[..., :3, 3] for f in frames]  # origins of frames 1..6
    u = frames[0][..., :3, 2]  # the joint-2 axis (parallel to joints 3 and 4)
    up = np.zeros_like(p[0])
    up[..., 2] = 1.0
    pairs = (
        (p[0] - 60.0 * scale * up, p[0]),  # the turning column above the fixed base
        (p[0] + 0.3 * o1 * u, p[0] + (o1 + 20.0 * scale) * u),  # shoulder housing
        (p[0] + o1 * u, p[1] + o1 * u),  # upper arm
        (p[1] + (o2 + 20.0 * scale) * u, p[1] + (o2 + 140.0 * scale) * u),  # elbow housing
        (p[1] + o2 * u, p[2] + o2 * u),  # forearm
        (p[2] + o2 * u, p[3]),  # wrist 1
        (p[3], p[4]),  # wrist 2
        (p[4], p[5]),  # wrist 3 to the flange
    )
    ends = np.stack([np.stack(pair, axis=-2) for pair in pairs], axis=-3)
    names = ("column", "shoulder", "upper arm", "elbow", "forearm", "wrist 1", "wrist 2", "wrist 3")
    return ends, scale * np.asarray(_UR5E_RADII_MM), names
