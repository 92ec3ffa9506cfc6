"""The probability-of-detection curve as PNG (matplotlib): each injected defect a hit or a
miss at its size, the fitted POD, its 95 % lower bound and the a50, a90 and a90/95 marks."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scanplan.judging.detection import DefectRun
from scanplan.judging.report.maps import MAX_PLOT_POINTS, _save


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
    return plot_detectability_maps([("", points_part, smallest_mm)], kind, out_path, title)


def plot_detectability_maps(
    maps: Sequence[tuple[str, np.ndarray, np.ndarray]],
    kind: str,
    out_path: str | os.PathLike,
    title: str,
) -> Path:
    """Detectability maps side by side on one colour scale, seen from above: per (label,
    sample points (k, 3), smallest `kind` depth found at 90 % (k,), inf: none) each sample
    coloured by that depth (grey: none found)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    shown = []
    for label, points, smallest in maps:
        keep = np.random.default_rng(0).permutation(len(points))[:MAX_PLOT_POINTS]
        shown.append((label, points[keep, :2], smallest[keep]))
    finite = np.concatenate([v[np.isfinite(v)] for _, _, v in shown])
    xy_all = np.concatenate([xy for _, xy, _ in shown])
    lo, hi = xy_all.min(axis=0), xy_all.max(axis=0)
    aspect = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.3, 3.0))
    n = len(shown)
    width = 8.0 if n == 1 else 5.0
    fig, axes = plt.subplots(
        1, n, figsize=(width * n, width * aspect + 1.2), layout="constrained", squeeze=False
    )
    norm = None
    if len(finite):
        # The colour scale spans the 1st-99th percentiles: a few edge samples stay legible.
        lo_mm, hi_mm = np.percentile(finite, [1, 99])
        norm = LogNorm(vmin=max(lo_mm, 1e-4), vmax=max(hi_mm, 1.01 * max(lo_mm, 1e-4)))
    dots = None
    for ax, (label, xy, values) in zip(axes[0], shown, strict=True):
        never = ~np.isfinite(values)
        ax.scatter(xy[never, 0], xy[never, 1], s=2, c="0.7", linewidths=0, label="none found")
        order = np.flatnonzero(~never)
        order = order[np.argsort(values[order])]  # the worst drawn last
        if len(order) and norm is not None:
            dots = ax.scatter(
                xy[order, 0], xy[order, 1], c=values[order], s=2, cmap="viridis",
                linewidths=0, norm=norm,
            )  # fmt: skip
        ax.set_aspect("equal")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        if label:
            found = values[np.isfinite(values)]
            median = f"median {np.median(found):.3g} mm" if len(found) else "none found"
            ax.set_title(f"{label}: {median}", fontsize=9)
    if dots is not None:
        fig.colorbar(dots, ax=axes[0].tolist(), label=f"smallest {kind} depth found at 90 % (mm)")
    fig.suptitle(f"{title}\npredicted detectability ({kind}, depth; grey: none found)", fontsize=9)
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path
