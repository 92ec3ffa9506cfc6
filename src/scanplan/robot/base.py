"""The `Robot` interface every arm model implements, and the frame maths they share.

Frames: `T_base_flange` is the tool flange in the robot's base frame as its controller shows
it (mm); joint vectors `q` are the controller's joint angles in rad.
"""

from __future__ import annotations

import warnings
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.spatial.transform import Rotation


@runtime_checkable
class Robot(Protocol):
    """A 6-axis arm with a closed-form inverse kinematics.

    joint_limits: (6, 2) rad, [lower, upper] per joint (±inf where a joint turns freely).
    """

    @property
    def name(self) -> str: ...

    @property
    def joint_limits(self) -> np.ndarray: ...

    def forward(self, q: np.ndarray) -> np.ndarray:
        """(…, 4, 4) `T_base_flange` in mm from joint angles (…, 6) in rad."""
        ...

    def inverse(self, T_base_flange: np.ndarray) -> np.ndarray:
        """(n, 8, 6) joint solutions in (-π, π] for (n, 4, 4) poses; NaN rows where a branch
        does not exist. A branch index is one arm configuration (shoulder, elbow, wrist)."""
        ...

    def singularity_terms(self, q: np.ndarray) -> np.ndarray:
        """(…, 3) signed distances from the wrist, elbow and shoulder singularities:
        wrist and elbow as sines (unitless), shoulder in mm. |terms| are the margins; their
        signs are the arm configuration, so a sign change along a pass is a flip."""
        ...

    @property
    def flange_axis(self) -> np.ndarray:
        """(3,) the unit direction out of the flange, in the flange frame as the controller
        shows it (a UR's and an ABB's z, a KUKA's x): a sensor straight out looks along it."""
        ...

    def link_capsules(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """The arm's moving links as capsules that enclose them: (…, k, 2, 3) segment ends in
        the base frame (mm), (k,) radii (mm) and the k link names. The fixed base below
        the first joint's housing is left out: it stands where the arm is mounted."""
        ...


def wrap(q: np.ndarray) -> np.ndarray:
    """Angles to [-π, π). By floor, not `%`: numpy's float remainder costs four times as
    much, and every inverse kinematics call wraps its eight solutions."""
    return q - (2 * np.pi) * np.floor((q + np.pi) * (1 / (2 * np.pi)))


def inv_rigid(T: np.ndarray) -> np.ndarray:
    out = np.zeros_like(T)
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = R
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def acos_or_nan(c: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """acos where |c| <= 1 (rounding at the boundary forgiven), NaN where out of reach."""
    ok = np.abs(c) <= 1.0 + tol
    return np.where(ok, np.arccos(np.clip(c, -1.0, 1.0)), np.nan)


def as_poses(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"flange poses must be (n, 4, 4), got {T.shape}")
    return T.reshape(-1, 4, 4)


def euler_zyx_deg(R: np.ndarray) -> np.ndarray:
    """(…, 3) KUKA A, B, C: intrinsic Z-Y'-X'' Euler angles in degrees."""
    with warnings.catch_warnings():
        # At B = ±90° scipy warns and sets C = 0; the angles still reproduce the rotation.
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(R).as_euler("ZYX", degrees=True)


def pose_arg(T: np.ndarray) -> str:
    """x,y,z (mm), A,B,C (deg, KUKA ZYX) as `--part-pose` and `--tcp` read them, to µm and
    millidegrees: a pose rounded coarser can tip a pass that skirts a singularity onto the
    other branch when `export` checks it again."""
    T = np.asarray(T, dtype=np.float64)
    abc = euler_zyx_deg(T[:3, :3])
    # round(..) + 0.0 turns -0.0 into 0.0, so nothing prints as "-0".
    return ",".join(
        f"{round(float(v), 3) + 0.0:.3f}".rstrip("0").rstrip(".") for v in (*T[:3, 3], *abc)
    )
