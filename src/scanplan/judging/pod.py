"""Probability of detection against size from hit/miss data, as MIL-HDBK-1823A fits it:
POD(a) = 1 / (1 + exp(-(b0 + b1·ln a))) by maximum likelihood; a50 and a90 from the fit and
a90/95, the upper end of a one-sided 95 % confidence interval on a90 by the delta method
(the Wald variance of ln a90 from the inverse of the observed information).

A fit needs both hits and misses overlapping in size; otherwise (`PodFit.status`) it says
what the data do show — every defect found, none found, or hits and misses separated at a
size — and leaves the numbers it cannot estimate None, never NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit

# One-sided 95 % normal quantile.
Z95 = 1.6448536269514722
LOGIT90 = math.log(9.0)


@dataclass(frozen=True)
class PodFit:
    """The fit of `hits` (n,) bool against `sizes_mm` (n,). status: 'fit', 'all_hit',
    'all_miss' or 'separated'; b0, b1 the logistic's coefficients on ln a (None without a
    fit); a50/a90/a90_95 mm (None where not estimable); note: what the data show, in words."""

    sizes_mm: np.ndarray
    hits: np.ndarray
    status: str
    b0: float | None = None
    b1: float | None = None
    a50: float | None = None
    a90: float | None = None
    a90_95: float | None = None
    note: str = ""
    cov: np.ndarray | None = field(default=None, repr=False)

    def pod(self, sizes_mm: np.ndarray) -> np.ndarray | None:
        if self.b0 is None or self.b1 is None:
            return None
        return expit(self.b0 + self.b1 * np.log(sizes_mm))

    def pod_lower95(self, sizes_mm: np.ndarray) -> np.ndarray | None:
        """The one-sided 95 % lower bound of POD at each size (delta method on the logit)."""
        if self.b0 is None or self.b1 is None or self.cov is None:
            return None
        x = np.log(sizes_mm)
        logit = self.b0 + self.b1 * x
        var = self.cov[0, 0] + 2 * x * self.cov[0, 1] + x * x * self.cov[1, 1]
        return expit(logit - Z95 * np.sqrt(np.maximum(var, 0.0)))

    def line(self, what: str) -> str:
        n, k = len(self.hits), int(self.hits.sum())
        head = f"{what}: {k}/{n} found"
        if self.status != "fit":
            return f"{head}: {self.note}"
        a9095 = f"{self.a90_95:.3g}" if self.a90_95 is not None else "not estimable"
        return f"{head}: a50 {self.a50:.3g} mm, a90 {self.a90:.3g} mm, a90/95 {a9095} mm" + (
            f" ({self.note})" if self.note else ""
        )

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "defects": len(self.hits),
            "found": int(self.hits.sum()),
            "a50_mm": self.a50,
            "a90_mm": self.a90,
            "a90_95_mm": self.a90_95,
            "b0": self.b0,
            "b1": self.b1,
            "confidence_bound": "delta method (Wald) on ln a90, one-sided 95 %",
            "note": self.note,
        }


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def fit_pod(sizes_mm: np.ndarray, hits: np.ndarray) -> PodFit:
    """The hit/miss POD fit (module docstring). Raises ValueError on no data or a size <= 0."""
    a = np.asarray(sizes_mm, float)
    y = np.asarray(hits, bool)
    if len(a) == 0 or len(a) != len(y):
        raise ValueError("no hit/miss data to fit")
    if not np.all(np.isfinite(a) & (a > 0)):
        raise ValueError("defect sizes must be finite and > 0")
    lo, hi = float(a.min()), float(a.max())
    if y.all():
        note = f"every defect found: a90 is below the smallest size tried, {lo:.3g} mm"
        return PodFit(a, y, "all_hit", a90=None, note=note)
    if not y.any():
        note = f"no defect found: a50 is above the largest size tried, {hi:.3g} mm"
        return PodFit(a, y, "all_miss", note=note)
    biggest_miss, smallest_hit = float(a[~y].max()), float(a[y].min())
    if biggest_miss < smallest_hit:
        note = (
            f"hits and misses separate at {biggest_miss:.3g}-{smallest_hit:.3g} mm: every "
            f"defect from {smallest_hit:.3g} mm found, none below; no logistic fit "
            "(the slope is unbounded), a90 <= that size, a90/95 not estimable"
        )
        return PodFit(a, y, "separated", a50=None, a90=smallest_hit, note=note)
    x = np.log(a)
    X = np.column_stack([np.ones_like(x), x])

    def nll(b: np.ndarray) -> tuple[float, np.ndarray]:
        eta = X @ b
        # -log L = sum log(1 + e^eta) - y eta, written without overflow.
        value = float(np.sum(np.logaddexp(0.0, eta) - y * eta))
        grad = X.T @ (expit(eta) - y)
        return value, grad

    start = np.array([0.0, 1.0])
    start[0] = -np.median(x)
    result = minimize(nll, start, jac=True, method="BFGS")
    b = result.x
    p = expit(X @ b)
    info = (X * (p * (1 - p))[:, None]).T @ X
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        cov = None
    b0, b1 = float(b[0]), float(b[1])
    if b1 <= 0:
        note = "POD does not grow with size over the sizes tried: no a50/a90"
        return PodFit(a, y, "flat", b0, b1, note=note, cov=cov)
    ln_a50 = -b0 / b1
    ln_a90 = (LOGIT90 - b0) / b1
    a90_95 = None
    if cov is not None:
        grad = np.array([-1.0 / b1, -(LOGIT90 - b0) / b1**2])
        se = math.sqrt(max(float(grad @ cov @ grad), 0.0))
        a90_95 = _finite(math.exp(ln_a90 + Z95 * se))
    notes = []
    a90 = math.exp(ln_a90)
    if a90 > hi:
        notes.append(f"a90 extrapolated beyond the largest size tried, {hi:.3g} mm")
    elif a90 < lo:
        notes.append(f"a90 extrapolated below the smallest size tried, {lo:.3g} mm")
    top = a >= np.quantile(a, 0.75)
    if y[top].mean() < 0.9:
        # The logistic climbs to 1; a plan that leaves surface unseen levels off below it.
        notes.append(
            f"only {y[top].mean():.0%} of the largest quarter ({a[top].min():.3g} mm and up) "
            "found: POD levels off below 90 % there, the fitted a90 assumes it does not"
        )
    note = "; ".join(notes)
    return PodFit(a, y, "fit", b0, b1, _finite(math.exp(ln_a50)), _finite(a90), a90_95, note, cov)
