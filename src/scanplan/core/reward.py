"""The paper's reward terms R_D, R_alpha, R_delta-s and their weighted sum (SPEC §5).

Shared by the environment, the geometric planner's cost and the metrics; the scale, α_max,
Δs_opt and the weights come from the one `ScanSpec`. Each term lies in
[-1, 0]; a missing measurement (NaN) is charged the full -1. Squares are written e * e: numpy
squares an array so but a scalar with pow, and the two differ in the last bit now and then,
so a batch of envs would not reward exactly as each env alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from scanplan.core.quantities import ScanSpec


def reward_distance(d_mm: ArrayLike, cfg: ScanSpec) -> np.ndarray:
    """R_D = -(W_d - D)^2 / (Z_r/2)^2 (the scale is `cfg.distance_scale_mm`, Z_r/2 unless set);
    -1 beyond the scale or with no valid point."""
    d = np.asarray(d_mm, dtype=np.float64)
    half = cfg.distance_scale_mm
    with np.errstate(invalid="ignore"):
        e = cfg.working_distance_mm - d
        r = -(e * e) / half**2
        return np.where(np.isfinite(d) & (r >= -1.0), r, -1.0)


def reward_alpha(alpha_rad: ArrayLike, cfg: ScanSpec) -> np.ndarray:
    """R_alpha = max(-1, -alpha^2 / alpha_max^2)."""
    a = np.asarray(alpha_rad, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(a), np.maximum(-1.0, -(a * a) / cfg.alpha_max_rad**2), -1.0)


def reward_advance(delta_s_mm: ArrayLike, cfg: ScanSpec) -> np.ndarray:
    """R_delta-s = max(-1, -(ds - ds_opt)^2 / ds_opt^2)."""
    s = np.asarray(delta_s_mm, dtype=np.float64)
    opt = cfg.delta_s_opt_mm
    with np.errstate(invalid="ignore"):
        e = s - opt
        return np.where(np.isfinite(s), np.maximum(-1.0, -(e * e) / opt**2), -1.0)


def reward_terms(
    d_mm: ArrayLike, alpha_rad: ArrayLike, delta_s_mm: ArrayLike, cfg: ScanSpec
) -> dict[str, np.ndarray]:
    """The three terms and their weighted sum: keys r_d, r_alpha, r_delta_s, reward."""
    r_d = reward_distance(d_mm, cfg)
    r_a = reward_alpha(alpha_rad, cfg)
    r_s = reward_advance(delta_s_mm, cfg)
    total = cfg.w_d * r_d + cfg.w_alpha * r_a + cfg.w_delta_s * r_s
    return {"r_d": r_d, "r_alpha": r_a, "r_delta_s": r_s, "reward": total}
