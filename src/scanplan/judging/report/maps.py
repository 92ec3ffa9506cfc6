"""The paper's error maps as PNG (matplotlib): scanned points seen from above, coloured by
distance error (diverging, mm) or orientation error (sequential, degrees); the in-spec map
(the surface to inspect seen from above: in spec, out of spec, not seen); the fragility map
(the share of perturbed trials each sample was in spec in); and the metrics table as Markdown.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scanplan.judging import CoverageMap, Metrics, Robustness, SurfaceState
from scanplan.judging.report.table import table_rows
from scanplan.sensor.cloud import PointCloud

MAX_PLOT_POINTS = 120_000
_POINT_PIXELS = 800  # cells across the longer side of a point map: about one per pixel
DISTANCE_CMAP = "RdBu_r"  # diverging: too far red, too close blue, W_d white
ORIENTATION_CMAP = "viridis"  # sequential from 0 deg


def _cloud_of(source: PointCloud | Metrics) -> PointCloud:
    cloud = source.cloud if isinstance(source, Metrics) else source
    if cloud is None or len(cloud.points_part) == 0:
        raise ValueError("no scanned point to draw")
    return cloud


def _subsample(n: int, k: int) -> np.ndarray:
    """Seeded random indices in random order: a stride would draw moire over the scan lines,
    and drawing in scan order would let the last pass hide the overlap."""
    rng = np.random.default_rng(0)
    return rng.permutation(n)[: min(n, k)]


def _limits(clouds: Sequence[PointCloud]) -> tuple[float, float]:
    """Shared colour limits: 98th percentile of |distance error| (mm) and of orientation (deg),
    so a few wall points do not wash out the surface (the colour bars extend beyond)."""
    d = np.concatenate([np.abs(c.distance_error_mm) for c in clouds])
    o = np.degrees(np.concatenate([c.orientation_error_rad for c in clouds]))
    return max(float(np.percentile(d, 98)), 0.05), max(float(np.percentile(o, 98)), 0.5)


def _point_image(xy: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, tuple]:
    """(image, extent): each cell of a grid about one pixel wide takes the value of one of its
    points, picked at random (NaN where none fell): what a scatter of one-pixel dots drawn in
    random order shows, at the cost of a sort instead of drawing each dot."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    cell = max(float(max(hi - lo)) / _POINT_PIXELS, 1e-9)
    shape = (int(np.floor((hi[1] - lo[1]) / cell)) + 1, int(np.floor((hi[0] - lo[0]) / cell)) + 1)
    ij = np.floor((xy - lo) / cell).astype(np.int64)
    flat = ij[:, 1] * shape[1] + ij[:, 0]
    rank = np.random.default_rng(0).permutation(len(flat))
    order = np.lexsort((rank, flat))  # by cell, then at random within it
    last = order[np.r_[flat[order][1:] != flat[order][:-1], True]]
    image = np.full(shape[0] * shape[1], np.nan)
    image[flat[last]] = values[last]
    extent = (lo[0], lo[0] + shape[1] * cell, lo[1], lo[1] + shape[0] * cell)
    return image.reshape(shape), extent


def _draw(ax, cloud: PointCloud, quantity: str, limit: float, title: str):
    ok = np.isfinite(cloud.points_part[:, :2]).all(axis=1)
    p = cloud.points_part[ok]
    if quantity == "distance":
        values, cmap, vmin = cloud.distance_error_mm[ok], DISTANCE_CMAP, -limit
    else:
        values, cmap, vmin = np.degrees(cloud.orientation_error_rad[ok]), ORIENTATION_CMAP, 0.0
    image, extent = _point_image(p[:, :2], values)
    artist = ax.imshow(
        image,
        origin="lower",
        extent=extent,
        cmap=cmap,
        vmin=vmin,
        vmax=limit,
        interpolation="nearest",
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title, fontsize=10)
    return artist


_LABELS = {
    "distance": ("distance_error.png", "distance error z_s − W_d (mm)", "Distance error"),
    "orientation": ("orientation_error.png", "orientation error α_i (°)", "Orientation error"),
}


def _save(fig, path: Path) -> None:
    """Write atomically: render to a temporary file beside the target, then rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.png")
    try:
        fig.savefig(tmp, dpi=150, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def plot_error_maps(
    source: PointCloud | Metrics,
    out_dir: str | os.PathLike,
    planner: str = "",
    part: str = "",
    distance_limit_mm: float | None = None,
    orientation_limit_deg: float | None = None,
) -> list[Path]:
    """Write `distance_error.png` and `orientation_error.png` of one scan into out_dir.

    source: a PointCloud, or Metrics (its sampled cloud; planner and part taken from it).
    Colour limits default to the 98th percentile of the data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cloud = _cloud_of(source)
    if isinstance(source, Metrics):
        planner, part = planner or source.planner, part or source.part
    d_lim, o_lim = _limits([cloud])
    limits = {"distance": distance_limit_mm or d_lim, "orientation": orientation_limit_deg or o_lim}
    written = []
    for quantity, (name, unit, label) in _LABELS.items():
        fig, ax = plt.subplots(figsize=(8, 6))
        title = f"{label} — {planner or 'trajectory'} on {part or 'part'}"
        artist = _draw(ax, cloud, quantity, limits[quantity], title)
        fig.colorbar(
            artist,
            ax=ax,
            label=unit,
            shrink=0.8,
            extend="both" if quantity == "distance" else "max",
        )
        path = Path(out_dir) / name
        _save(fig, path)
        plt.close(fig)
        written.append(path)
    return written


def plot_comparison(
    sources: Sequence[tuple[str, PointCloud | Metrics]],
    quantity: str,
    out_path: str | os.PathLike,
    part: str = "",
) -> Path:
    """Side-by-side maps of several planners with one shared colour scale (the paper's
    figure pairs). sources: (label, cloud or metrics); quantity: 'distance' or 'orientation'."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if quantity not in _LABELS:
        raise ValueError(f"unknown quantity {quantity!r}: use distance or orientation")
    if not sources:
        raise ValueError("nothing to compare")
    clouds = [_cloud_of(src) for _, src in sources]
    d_lim, o_lim = _limits(clouds)
    limit = d_lim if quantity == "distance" else o_lim
    _, unit, label = _LABELS[quantity]
    # Panels take the part's aspect (equal axes), so the figure height follows it: no empty band.
    xy = np.concatenate([c.points_part[:, :2] for c in clouds])
    xy = xy[np.isfinite(xy).all(axis=1)]
    extent = np.ptp(xy, axis=0) if len(xy) else np.ones(2)
    aspect = float(np.clip(extent[1] / max(extent[0], 1e-9), 0.3, 3.0))
    fig, axes = plt.subplots(
        1,
        len(sources),
        figsize=(5.5 * len(sources) + 1.0, 5.5 * aspect + 1.2),
        squeeze=False,
        layout="compressed",
    )
    artists = [
        _draw(ax, cloud, quantity, limit, name)
        for ax, (name, _), cloud in zip(axes[0], sources, clouds, strict=True)
    ]
    fig.suptitle(f"{label} — {part}" if part else label)
    fig.colorbar(
        artists[0],
        ax=list(axes[0]),
        label=unit,
        shrink=0.8,
        extend="both" if quantity == "distance" else "max",
    )
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path


# Three colours that stay apart for colour-blind readers too (ColorBrewer Dark2 + grey).
COVERAGE_COLOURS = {
    SurfaceState.IN_SPEC: ("#1b9e77", "in spec"),
    SurfaceState.OUT_OF_SPEC: ("#d95f02", "out of spec"),
    SurfaceState.UNSEEN: ("#b4b4b4", "not seen"),
}
COVERAGE_MAP_NAME = "in_spec_coverage.png"
_MAP_PIXELS = 700  # cells across the longer side of a coverage map


def _coverage_of(source: Metrics) -> CoverageMap:
    if source.coverage_map is None or len(source.coverage_map.state) == 0:
        raise ValueError("no surface sample to draw the in-spec map")
    return source.coverage_map


def _coverage_image(
    cmap: CoverageMap, lo: np.ndarray, cell: float, shape: tuple[int, int]
) -> np.ndarray:
    """RGBA image (rows = y, cols = x) of the majority state of the samples in each cell.
    A cell that drew no sample takes the majority of its 3 x 3 neighbourhood (random samples
    leave a few such holes); one with none around it is off the part and stays transparent."""
    from matplotlib.colors import to_rgba

    ij = np.floor((cmap.points_part[:, :2] - lo) / cell).astype(np.int64)
    ij = np.clip(ij, 0, np.array(shape[::-1]) - 1)
    flat = ij[:, 1] * shape[1] + ij[:, 0]
    counts = np.stack(
        [
            np.bincount(flat[cmap.state == s], minlength=shape[0] * shape[1]).reshape(shape)
            for s in SurfaceState
        ]
    )
    padded = np.pad(counts, ((0, 0), (1, 1), (1, 1)))
    around = sum(
        padded[:, 1 + di : 1 + di + shape[0], 1 + dj : 1 + dj + shape[1]]
        for di in (-1, 0, 1)
        for dj in (-1, 0, 1)
    )
    empty = counts.sum(axis=0) == 0
    counts = np.where(empty[None], around, counts)
    palette = np.array([to_rgba(COVERAGE_COLOURS[s][0]) for s in SurfaceState])
    image = palette[counts.argmax(axis=0)]
    image[counts.sum(axis=0) == 0] = 0.0
    return image


def _draw_coverage(ax, cmap: CoverageMap, lo: np.ndarray, hi: np.ndarray, title: str) -> None:
    cell = float(max(hi - lo)) / _MAP_PIXELS
    # Coarse enough that a cell holds a few samples: a solid picture, not speckle.
    span = np.maximum(hi - lo, 1e-9)
    per_mm2 = len(cmap.state) / (span[0] * span[1])
    cell = max(cell, math.sqrt(4.0 / max(per_mm2, 1e-12)))
    shape = (max(1, int(math.ceil(span[1] / cell))), max(1, int(math.ceil(span[0] / cell))))
    image = _coverage_image(cmap, lo, cell, shape)
    ax.imshow(
        image,
        origin="lower",
        extent=(lo[0], lo[0] + shape[1] * cell, lo[1], lo[1] + shape[0] * cell),
        interpolation="nearest",
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title, fontsize=10)


def _coverage_legend(fig, maps: Sequence[CoverageMap] = ()) -> None:
    from matplotlib.patches import Patch

    handles = []
    for state in (SurfaceState.IN_SPEC, SurfaceState.OUT_OF_SPEC, SurfaceState.UNSEEN):
        colour, label = COVERAGE_COLOURS[state]
        if len(maps) == 1:
            label += f" ({maps[0].fraction(state):.1%})"
        handles.append(Patch(facecolor=colour, edgecolor="none", label=label))
    fig.legend(handles=handles, loc="outside lower center", ncol=3, frameon=False)


def _tolerance_text(metrics: Metrics) -> str:
    return f"|z_s − W_d| ≤ {metrics.tolerance_mm:g} mm, α_i ≤ {metrics.tolerance_deg:g}°"


def plot_coverage_map(
    source: Metrics, out_path: str | os.PathLike, planner: str = "", part: str = ""
) -> Path:
    """The in-spec map of one scan, seen from above: where the surface to inspect is in spec,
    out of spec or not seen, the in-spec fraction in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cmap = _coverage_of(source)
    planner, part = planner or source.planner or "trajectory", part or source.part or "part"
    xy = cmap.points_part[:, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    aspect = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.3, 3.0))
    fig, ax = plt.subplots(figsize=(8, 8 * aspect + 1.0), layout="constrained")
    _draw_coverage(
        ax,
        cmap,
        lo,
        hi,
        f"In-spec coverage {source.in_spec_coverage:.1%}{_of_ceiling(source)} — {planner} on "
        f"{part}\n"
        f"({_tolerance_text(source)}, ≥ 1 point per "
        f"{source.in_spec_cell_mm:g} mm square)",
    )
    _coverage_legend(fig, [cmap])
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path


def plot_fragility_map(robust: Robustness, out_path: str | os.PathLike, title: str) -> Path:
    """The fragility map, seen from above: each nominal sample of the surface to inspect
    coloured by the share of perturbed trials that held it in spec (yellow: always)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xy = robust.points_part[:, :2]
    keep = _subsample(len(xy), MAX_PLOT_POINTS)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    aspect = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.3, 3.0))
    fig, ax = plt.subplots(figsize=(8, 8 * aspect + 1.0), layout="constrained")
    # The least steady drawn last: a fragile sample stays visible among sound ones.
    order = keep[np.argsort(-robust.in_spec_share[keep], kind="stable")]
    dots = ax.scatter(
        xy[order, 0],
        xy[order, 1],
        c=robust.in_spec_share[order],
        s=2,
        cmap=ORIENTATION_CMAP,
        vmin=0.0,
        vmax=1.0,
        linewidths=0,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(
        f"{title}\nin-spec coverage over {len(robust.per_trial)} trials: mean "
        f"{robust.mean:.1%}, p5 {robust.p5:.1%}, worst {robust.worst:.1%}"
    )
    fig.colorbar(dots, ax=ax, label="share of trials in spec")
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path


def _of_ceiling(metrics: Metrics) -> str:
    """' (84% of the ceiling)', or nothing where the ceiling was not measured."""
    share = metrics.in_spec_of_ceiling
    return "" if share is None else f" ({share:.0%} of the ceiling)"


def plot_coverage_comparison(
    sources: Sequence[tuple[str, Metrics]], out_path: str | os.PathLike, part: str = ""
) -> Path:
    """Side-by-side in-spec maps of several planners, each panel titled with its fraction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not sources:
        raise ValueError("nothing to compare")
    maps = [_coverage_of(m) for _, m in sources]
    xy = np.concatenate([c.points_part[:, :2] for c in maps])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    aspect = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9), 0.3, 3.0))
    fig, axes = plt.subplots(
        1,
        len(sources),
        figsize=(5.5 * len(sources) + 1.0, 5.5 * aspect + 1.6),
        squeeze=False,
        layout="constrained",
    )
    for ax, (name, metrics), cmap in zip(axes[0], sources, maps, strict=True):
        _draw_coverage(
            ax,
            cmap,
            lo,
            hi,
            f"{name}: {metrics.in_spec_coverage:.1%} in spec{_of_ceiling(metrics)}",
        )
    first = sources[0][1]
    fig.suptitle(
        f"In-spec coverage — {part or first.part} ({_tolerance_text(first)}, ≥ 1 point per "
        f"{first.in_spec_cell_mm:g} mm square)"
    )
    _coverage_legend(fig)
    path = Path(out_path)
    _save(fig, path)
    plt.close(fig)
    return path


def metrics_table_markdown(metrics: Sequence[Metrics], labels: Sequence[str] | None = None) -> str:
    """One column per trajectory, one row per metric."""
    if not metrics:
        raise ValueError("no metrics to tabulate")
    names = list(labels) if labels else [m.planner or f"#{i}" for i, m in enumerate(metrics)]
    dicts = [m.to_json_dict() for m in metrics]
    lines = [
        "| metric | " + " | ".join(names) + " |",
        "|---|" + "---:|" * len(names),
    ]
    for label, cells in table_rows(dicts):
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
