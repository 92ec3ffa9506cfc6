"""The probability-of-detection curve as PNG (matplotlib): each injected defect a hit or a
miss at its size, the fitted POD, its 95 % lower bound and the a50, a90 and a90/95 marks."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from scanplan.metrics.detection import DefectRun
from scanplan.report.maps import MAX_PLOT_POINTS, _save


def plot_pod(run: DefectRun, out_path: str | os.PathLike, title: str) -> Path:
    """The POD curve of `run` (log size axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes, hits, fit = run.sizes_mm, run.hits, run.fit
    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    jitter = np.random.default_rng(0).uniform(-0.02, 0.02, len(sizes))
    for mask, colour, label in ((hits, "tab:green", "found"), (~hits, "tab:red", "missed")):
        ax.scatter(
            sizes[mask], hits[mask].astype(float) + jitter[mask], s=10, c=colour, alpha=0.6,
            linewidths=0, label=f"{label} ({int(mask.sum())})",
        )  # fmt: skip
    grid = np.geomspace(sizes.min(), sizes.max(), 200)
    pod = fit.pod(grid)
    if pod is not None:
        ax.plot(grid, pod, "k-", label="POD (logistic on ln a, ML)")
        lower = fit.pod_lower95(grid)
        if lower is not None:
            ax.plot(grid, lower, "k--", label="95 % lower bound")
    for value, name, style in (
        (fit.a50, "a50", ":"),
        (fit.a90, "a90", "-."),
        (fit.a90_95, "a90/95", "--"),
    ):
        if value is not None and sizes.min() <= value <= sizes.max():
            ax.axvline(value, color="tab:blue", linestyle=style, lw=1)
            ax.text(value, 0.5, f" {name} {value:.3g}", color="tab:blue", rotation=90, va="center")
    ax.axhline(0.9, color="grey", lw=0.5)
    ax.set_xscale("log")
    ax.set_ylim(-0.08, 1.08)
    ax.set_xlabel(f"{run.kind} depth a (mm)")
    ax.set_ylabel("probability of detection")
    ax.set_title(f"{title}\n{fit.line(run.kind)}", fontsize=9)
    ax.legend(loc="center right", fontsize=8)
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path


def plot_detectability(
    points_part: np.ndarray,
    smallest_mm: np.ndarray,
    kind: str,
    out_path: str | os.PathLike,
    title: str,
) -> Path:
    """The detectability map seen from above: each sample of the surface to inspect coloured
    by the smallest `kind` depth found there with 90 % probability (grey: none)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    xy = points_part[:, :2]
    keep = np.random.default_rng(0).permutation(len(xy))[:MAX_PLOT_POINTS]
    finite = np.isfinite(smallest_mm[keep])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    aspect = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.3, 3.0))
    fig, ax = plt.subplots(figsize=(8, 8 * aspect + 1.0), layout="constrained")
    never = keep[~finite]
    ax.scatter(xy[never, 0], xy[never, 1], s=2, c="0.7", linewidths=0, label="none found")
    shown = keep[finite]
    order = shown[np.argsort(smallest_mm[shown])]  # the worst drawn last
    values = smallest_mm[order]
    if len(values):
        # The colour scale spans the 1st-99th percentiles: a few edge samples stay legible.
        lo_mm, hi_mm = np.percentile(values, [1, 99])
        dots = ax.scatter(
            xy[order, 0], xy[order, 1], c=values, s=2, cmap="viridis", linewidths=0,
            norm=LogNorm(vmin=max(lo_mm, 1e-4), vmax=max(hi_mm, 1.01 * max(lo_mm, 1e-4))),
        )  # fmt: skip
        fig.colorbar(dots, ax=ax, label=f"smallest {kind} depth found at 90 % (mm)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{title}\npredicted detectability ({kind}, depth)", fontsize=9)
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path
