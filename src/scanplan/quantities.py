"""Profile-level quantities of SPEC §2 — D, signed alpha, per-point alpha_i, delta-s.

The environment, the planners and the metrics all call these, so the agent's reward and the
report's numbers can never disagree. Every function works on leading batch dimensions.
"""

from __future__ import annotations

import numpy as np


def mean_distance(z_sensor: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """D: mean z_s of the valid points. (..., N) -> (...); NaN where no point is valid."""
    count = valid.sum(axis=-1)
    total = np.where(valid, z_sensor, 0.0).sum(axis=-1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def mean_normal(normals_part: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Unit mean of the valid points' normals. (..., N, 3) -> (..., 3); NaN if none valid."""
    total = np.where(valid[..., None], normals_part, 0.0).sum(axis=-2)
    norm = np.linalg.norm(total, axis=-1, keepdims=True)
    return np.where(norm > 0, total / np.where(norm > 0, norm, 1.0), np.nan)


def signed_alpha(normals_part: np.ndarray, valid: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """alpha = atan2(n.y_s, -n.z_s) with n the mean valid normal: the pitch increment about +x_s
    that would align the beam with the surface. (..., N, 3), (..., N), (..., 4, 4) -> (...),
    NaN where no point is valid."""
    n = mean_normal(normals_part, valid)
    y_s = poses[..., :3, 1]
    z_s = poses[..., :3, 2]
    return np.arctan2(np.sum(n * y_s, axis=-1), -np.sum(n * z_s, axis=-1))


def point_orientation_error(normals_part: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """alpha_i = acos(-z_s . n_i) per point, radians; includes what pitch cannot correct.
    (..., N, 3), (..., 4, 4) -> (..., N)."""
    z_s = poses[..., None, :3, 2]
    return np.arccos(np.clip(-np.sum(normals_part * z_s, axis=-1), -1.0, 1.0))


def advance(
    points_prev: np.ndarray,
    valid_prev: np.ndarray,
    points_next: np.ndarray,
    valid_next: np.ndarray,
    scan_direction: np.ndarray,
) -> np.ndarray:
    """delta-s: signed 3-D advance between consecutive profiles (SPEC §2).

    Over the pixel columns valid in both, the mean of sign(d_i . u) * |d_i|, d_i the
    displacement of column i's point. (..., N, 3) x2, (..., N) x2, (3,) or (..., 3) -> (...);
    NaN where no column is valid in both.
    """
    both = valid_prev & valid_next
    d = np.where(both[..., None], points_next - points_prev, 0.0)
    u = np.asarray(scan_direction, dtype=np.float64)
    if u.ndim > 1:
        u = u[..., None, :]
    signed = np.sign(np.sum(d * u, axis=-1)) * np.linalg.norm(d, axis=-1)
    count = both.sum(axis=-1)
    return np.where(count > 0, signed.sum(axis=-1) / np.maximum(count, 1), np.nan)
