"""Closed-form kinematics of 6-axis arms with an ortho-parallel basis and a spherical wrist.

The geometry and the eight-branch inverse are those of Brandstötter, Angerer & Hofbaur (2014),
"An analytical solution of the inverse kinematics problem of industrial serial manipulators
with an ortho-parallel basis and a spherical wrist" (Austrian Robotics Workshop): seven
lengths a1, a2, b, c1, c2, c3, c4 (mm here) describe KUKA, ABB, Fanuc, Stäubli... arms.
Controller joints relate to the paper's angles by q_ctrl = sign · (q_opw + offset).
The paper's tool frame is turned into the controller's flange frame by `flange`, and its
base frame sits at `base` in the controller's base frame, so `T_base_flange` is what the
pendant shows. Fanuc's J3 is measured from the horizontal (the J2/J3 interaction):
`j3_from_horizontal` converts it to the serial joint the geometry needs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scanplan.robot.base import acos_or_nan, as_poses, inv_rigid, wrap


def _rz(t: np.ndarray) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    R = np.zeros((*np.shape(t), 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1] = c, -s, s, c
    R[..., 2, 2] = 1.0
    return R


def _ry(t: np.ndarray) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    R = np.zeros((*np.shape(t), 3, 3))
    R[..., 0, 0], R[..., 0, 2], R[..., 2, 0], R[..., 2, 2] = c, s, -s, c
    R[..., 1, 1] = 1.0
    return R


@dataclass(frozen=True, eq=False)  # array fields: == would be ambiguous
class OPWRobot:
    """An OPW arm. Lengths in mm; offsets, limits in rad; `sign` ±1 per joint.

    joint_limits: (6, 2) rad, the controller's software limits per joint.
    base:   (4, 4) the paper's base frame in the controller's base frame (mm).
    flange: (4, 4) the controller's flange frame in the paper's tool frame.
    """

    name: str
    a1: float
    a2: float
    b: float
    c1: float
    c2: float
    c3: float
    c4: float
    offsets: tuple[float, ...] = (0.0,) * 6
    sign: tuple[int, ...] = (1,) * 6
    limits: tuple[tuple[float, float], ...] = ((-np.pi, np.pi),) * 6
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    flange: np.ndarray = field(default_factory=lambda: np.eye(4))
    j3_from_horizontal: bool = False

    def __post_init__(self) -> None:
        if self.c2 <= 0 or np.hypot(self.a2, self.c3) <= 0:
            raise ValueError(f"robot {self.name}: c2 and hypot(a2, c3) must be > 0")
        if len(self.offsets) != 6 or len(self.sign) != 6 or len(self.limits) != 6:
            raise ValueError(f"robot {self.name}: offsets, sign and limits need 6 entries")

    @property
    def joint_limits(self) -> np.ndarray:
        return np.asarray(self.limits, dtype=np.float64)

    # --- joint conventions -----------------------------------------------------------------
    def _to_opw(self, q: np.ndarray) -> np.ndarray:
        q = np.array(q, dtype=np.float64)
        if self.j3_from_horizontal:
            q[..., 2] = q[..., 2] + q[..., 1]
        return q * np.asarray(self.sign, dtype=np.float64) - np.asarray(self.offsets)

    def _from_opw(self, q_opw: np.ndarray) -> np.ndarray:
        q = (q_opw + np.asarray(self.offsets)) * np.asarray(self.sign, dtype=np.float64)
        if self.j3_from_horizontal:
            q[..., 2] = q[..., 2] - q[..., 1]
        return wrap(q)

    # --- kinematics --------------------------------------------------------------------------
    def forward(self, q: np.ndarray) -> np.ndarray:
        t = self._to_opw(q)
        t1, t2, t3, t4, t5, t6 = np.moveaxis(t, -1, 0)
        psi3, k = np.arctan2(self.a2, self.c3), np.hypot(self.a2, self.c3)
        # Wrist centre in the arm's plane (frame 1), then turned by joint 1.
        cx1 = self.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + self.a1
        cz1 = self.c2 * np.cos(t2) + k * np.cos(t2 + t3 + psi3)
        c1, s1 = np.cos(t1), np.sin(t1)
        centre = np.stack([cx1 * c1 - self.b * s1, cx1 * s1 + self.b * c1, cz1 + self.c1], -1)
        R = _rz(t1) @ _ry(t2 + t3) @ _rz(t4) @ _ry(t5) @ _rz(t6)
        T = np.zeros((*t1.shape, 4, 4))
        T[..., :3, :3] = R
        T[..., :3, 3] = centre + self.c4 * R[..., :, 2]
        T[..., 3, 3] = 1.0
        return self.base @ T @ self.flange

    def inverse(self, T_base_flange: np.ndarray) -> np.ndarray:
        """(n, 8, 6); index = 4·wrist + 2·shoulder + elbow (the paper's i…viii)."""
        # A pose whose wrist centre lies on an axis (s = 0, or a forearm along the shoulder)
        # divides by zero: its angles come out NaN, the pose unreachable, without a warning.
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._inverse(T_base_flange)

    def _inverse(self, T_base_flange: np.ndarray) -> np.ndarray:
        T = inv_rigid(self.base) @ as_poses(T_base_flange) @ inv_rigid(self.flange)
        n = len(T)
        R = T[:, :3, :3]
        c = T[:, :3, 3] - self.c4 * R[:, :, 2]
        # Shoulder: joint 1 points the arm's plane at the wrist centre, or away from it.
        rho = c[:, 0] ** 2 + c[:, 1] ** 2 - self.b**2
        nx1 = np.sqrt(np.where(rho >= 0, rho, np.nan)) - self.a1
        phi = np.arctan2(c[:, 1], c[:, 0])
        lean = np.arctan2(self.b, nx1 + self.a1)
        t1 = np.stack([phi - lean, phi + lean - np.pi], axis=1)  # (n, 2)
        # Elbow: the triangle joint 2 - joint 3 - wrist centre, in the arm's plane.
        dz = c[:, 2] - self.c1
        reach_x = np.stack([nx1, nx1 + 2 * self.a1], axis=1)  # (n, 2): front, back
        s_sq = reach_x**2 + dz[:, None] ** 2
        s = np.sqrt(s_sq)
        k_sq = self.a2**2 + self.c3**2
        k = np.sqrt(k_sq)
        psi3 = np.arctan2(self.a2, self.c3)
        g2 = acos_or_nan((s_sq + self.c2**2 - k_sq) / (2 * s * self.c2))
        g3 = acos_or_nan((s_sq - self.c2**2 - k_sq) / (2 * self.c2 * k))
        sgn = np.array([-1.0, 1.0])  # elbow branch
        aim = np.stack([np.arctan2(nx1, dz), -np.arctan2(nx1 + 2 * self.a1, dz)], axis=1)
        t2 = sgn * g2[..., None] + aim[..., None]  # (n, 2 shoulder, 2 elbow)
        t3 = -sgn * g3[..., None] - psi3
        t1b = np.broadcast_to(t1[..., None], t2.shape)
        # Wrist: R_ce = Rz(q4) Ry(q5) Rz(q6) is what joints 1-3 leave to the wrist.
        # Written out (the batched 3x3 products cost a third of the call): with
        # u = Rz(q1)ᵀ's first row times R, v its second, w = R's last row and a = q2 + q3,
        # R_ce's rows are ca·u - sa·w, v and sa·u + ca·w.
        c1, s1 = np.cos(t1)[..., None, None], np.sin(t1)[..., None, None]  # (n, 2, 1, 1)
        Rn = R[:, None, None]  # (n, 1, 1, 3, 3)
        u = c1 * Rn[..., 0, :] + s1 * Rn[..., 1, :]  # (n, 2, 1, 3)
        v = -s1 * Rn[..., 0, :] + c1 * Rn[..., 1, :]
        w = Rn[..., 2, :]
        ca, sa = np.cos(t2 + t3)[..., None], np.sin(t2 + t3)[..., None]  # (n, 2, 2, 1)
        row0, row2 = ca * u - sa * w, sa * u + ca * w  # (n, 2, 2, 3)
        v = np.broadcast_to(v, row0.shape)
        t5 = np.arctan2(np.hypot(row0[..., 2], v[..., 2]), row2[..., 2])
        t4 = np.arctan2(v[..., 2], row0[..., 2])
        t6 = np.arctan2(row2[..., 1], -row2[..., 0])
        # On the wrist singularity only q4 ± q6 is defined: put it all on q6.
        singular = np.sin(t5) < 1e-12
        phi46 = np.arctan2(-row0[..., 1], v[..., 1])
        t4 = np.where(singular, 0.0, t4)
        t6 = np.where(singular, np.where(row2[..., 2] > 0, phi46, -phi46), t6)
        arm = np.stack([t1b, t2, t3], axis=-1).reshape(n, 4, 3)
        wrist = np.stack([t4, t5, t6], axis=-1).reshape(n, 4, 3)
        flipped = wrist + np.array([np.pi, 0.0, -np.pi])
        flipped[..., 1] *= -1
        q_opw = np.concatenate(
            [np.concatenate([arm, wrist], axis=-1), np.concatenate([arm, flipped], axis=-1)],
            axis=1,
        )
        q = self._from_opw(q_opw)
        q[np.isnan(q).any(axis=2)] = np.nan
        return q

    @property
    def flange_axis(self) -> np.ndarray:
        # The paper's tool z (out of the flange) in the controller's flange frame.
        axis: np.ndarray = self.flange[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        return axis

    def link_capsules(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """Capsules along the kinematic chain: the column from a third of the shoulder height
        to joint 2, the upper arm (joint 2 to 3), the forearm through its offset a2 to the
        wrist centre, and the wrist to the flange. Radii are fractions of the arm's length
        c2 + √(a2² + c3²), set so that they enclose the KR 6 R900 and IRB 2400 of the
        makers' dimension drawings (column Ø ~190 / ~320 mm, upper arm ~130 / ~220 mm)."""
        t = self._to_opw(q)
        t1, t2, t3 = t[..., 0], t[..., 1], t[..., 2]
        theta = t2 + t3
        shape = t1.shape
        zero, one = np.zeros(shape), np.ones(shape)

        def planar(x: np.ndarray, z: np.ndarray) -> np.ndarray:  # arm plane -> paper base
            c, s = np.cos(t1), np.sin(t1)
            return np.stack([x * c - self.b * s, x * s + self.b * c, z], axis=-1)

        foot = np.stack([zero, zero, one * self.c1 / 3], axis=-1)
        top = np.stack([zero, zero, one * self.c1], axis=-1)
        j2 = planar(one * self.a1, one * self.c1)
        j3x, j3z = self.a1 + self.c2 * np.sin(t2), self.c1 + self.c2 * np.cos(t2)
        j3 = planar(j3x, j3z)
        ex, ez = j3x + self.a2 * np.cos(theta), j3z - self.a2 * np.sin(theta)
        elbow = planar(ex, ez)
        wrist = planar(ex + self.c3 * np.sin(theta), ez + self.c3 * np.cos(theta))
        flange = self.forward(q)[..., :3, 3]
        ends = np.stack(
            [
                np.stack(pair, axis=-2)
                for pair in ((foot, top), (top, j2), (j2, j3), (j3, elbow), (elbow, wrist))
            ],
            axis=-3,
        )
        ends = ends @ self.base[:3, :3].T + self.base[:3, 3]
        flange_link = np.stack([ends[..., 4, 1, :], flange], axis=-2)
        ends = np.concatenate([ends, flange_link[..., None, :, :]], axis=-3)
        size = self.c2 + float(np.hypot(self.a2, self.c3))
        radii = size * np.array([0.11, 0.11, 0.075, 0.065, 0.065, 0.05])
        return ends, radii, ("column", "shoulder", "upper arm", "elbow", "forearm", "wrist")

    def singularity_terms(self, q: np.ndarray) -> np.ndarray:
        """(…, 3): sin q5 (wrist: axes 4 and 6 align), sin(q3 + ψ3) (elbow: arm stretched
        or folded) and, in mm, the wrist centre's distance from the joint-1 axis in the
        arm's plane (shoulder). For b = 0 their product is det J up to c2·√(a2²+c3²)."""
        t = self._to_opw(q)
        t2, t3 = t[..., 1], t[..., 2]
        psi3, k = np.arctan2(self.a2, self.c3), np.hypot(self.a2, self.c3)
        shoulder = self.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + self.a1
        return np.stack([np.sin(t[..., 4]), np.sin(t3 + psi3), shoulder], axis=-1)
