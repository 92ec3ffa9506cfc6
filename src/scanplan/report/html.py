"""The self-contained HTML report: interactive 3-D views (plotly), metrics, maps, training.

One file, plotly.js inlined once, PNGs embedded as data URIs, so it opens offline and can be
mailed as is. The metrics table is built from the same `to_json_dict()` the CLI prints.
"""

from __future__ import annotations

import base64
import html
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanplan.cell import Cell
from scanplan.cloud import PointCloud
from scanplan.files import atomic_write_text
from scanplan.metrics import CoverageMap, SurfaceState
from scanplan.part import Part
from scanplan.report.maps import COVERAGE_COLOURS
from scanplan.report.scene import (
    VIEW_COLOURS,
    ArmPoses,
    add_arm,
    cell_traces,
    part_trace,
    path_trace,
)
from scanplan.report.table import lookup, table_rows, tolerance_label
from scanplan.report.training import CURVES, read_log
from scanplan.trajectory import Trajectory

# Enough for a smooth picture, small enough that the file stays a few MB.
MAX_POINTS_PER_PLANNER = 25_000
MAX_ARROWS = 120


@dataclass(frozen=True)
class PlannerResult:
    """What the report shows of one planner: its path, its simulated scan, its numbers, and
    for a plan made for an arm, the cell and the arm along the path."""

    name: str
    trajectory: Trajectory
    cloud: PointCloud
    metrics: dict
    coverage: CoverageMap | None = None
    cell: Cell | None = None
    arm: ArmPoses | None = None


def metrics_table_html(results: list[PlannerResult]) -> str:
    head = "".join(f"<th>{html.escape(r.name)}</th>" for r in results)
    rows = [
        f"<tr><th>{html.escape(label)}</th>" + "".join(f"<td>{v}</td>" for v in values) + "</tr>"
        for label, values in table_rows([r.metrics for r in results])
    ]
    return f"<table><tr><th>metric</th>{head}</tr>{''.join(rows)}</table>"


def _in_spec_headline(results: list[PlannerResult]) -> str:
    """The headline figure, one per planner: the in-spec coverage and its tolerance."""
    values = [(r.name, lookup(r.metrics, ("in_spec_coverage",))) for r in results]
    shown = [
        f"{html.escape(name)} <b>{v:.1%}</b>" for name, v in values if isinstance(v, int | float)
    ]
    if not shown:
        return ""
    tolerance = html.escape(tolerance_label([r.metrics for r in results]).strip(" ()"))
    return (
        "<p class='headline'>In-spec coverage"
        + (f" <span class='note'>({tolerance})</span>" if tolerance else "")
        + ": "
        + " · ".join(shown)
        + "</p>"
    )


def _subsample(n: int, k: int, seed: int = 0) -> np.ndarray:
    if n <= k:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=k, replace=False))


def _planner_figure(part: Part, part_mesh, result: PlannerResult, distance_limit_mm: float):
    import plotly.graph_objects as go

    traj, cloud = result.trajectory, result.cloud
    pos = traj.positions_mm
    traces = [part_mesh]
    views = traj.meta.get("views") or []
    if len(views) > 1:
        # Each view's poses in its own colour (a view is a block of swaths), moves in grey.
        traces.append(path_trace(pos, ~traj.scanning, "moves", "gray", 2))
        for k, v in enumerate(views):
            in_view = (traj.swath >= v["first_swath"]) & (traj.swath <= v["last_swath"])
            axis = ", ".join(f"{c:.2f}" for c in v["axis"])
            colour = VIEW_COLOURS[k % len(VIEW_COLOURS)]
            traces.append(path_trace(pos, in_view & traj.scanning, f"view {k} ({axis})", colour, 4))
    else:
        traces.append(path_trace(pos, np.ones(len(pos), bool), "sensor path", "black", 3))
    # Sensor poses as arrows: the laser axis z_s drawn 60 mm long from the emitter.
    scan_idx = np.flatnonzero(traj.scanning)
    arrows = scan_idx[np.linspace(0, len(scan_idx) - 1, min(MAX_ARROWS, len(scan_idx))).astype(int)]
    tips = pos[arrows] + traj.poses[arrows, :3, 2] * 60.0
    segments = np.full((3 * len(arrows), 3), np.nan)  # NaN rows break the line between arrows
    segments[0::3], segments[1::3] = pos[arrows], tips
    traces.append(
        go.Scatter3d(
            x=segments[:, 0], y=segments[:, 1], z=segments[:, 2], mode="lines",
            line={"color": "royalblue", "width": 4}, name="laser axis (z_s)", connectgaps=False,
        )
    )  # fmt: skip
    keep = _subsample(len(cloud.points_part), MAX_POINTS_PER_PLANNER)
    p = cloud.points_part[keep]
    dist = cloud.distance_error_mm[keep]
    orient = np.degrees(cloud.orientation_error_rad[keep])
    traces.append(
        go.Scatter3d(
            x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", name="scan points",
            marker={
                "size": 1.6, "color": dist, "colorscale": "RdBu_r",
                "cmin": -distance_limit_mm, "cmax": distance_limit_mm,
                "colorbar": {"title": "distance error (mm)"},
            },
            hovertemplate="z_s − W_d %{marker.color:.3f}<extra></extra>",
        )
    )  # fmt: skip
    points_index = len(traces) - 1
    fig = go.Figure(traces)
    orient_max = float(np.percentile(orient, 99)) if len(orient) else 1.0
    distance_style = {
        "marker.color": [dist], "marker.colorscale": ["RdBu_r"],
        "marker.cmin": [-distance_limit_mm], "marker.cmax": [distance_limit_mm],
        "marker.colorbar.title.text": ["distance error (mm)"],
    }  # fmt: skip
    orientation_style = {
        "marker.color": [orient], "marker.colorscale": ["Viridis"],
        "marker.cmin": [0.0], "marker.cmax": [max(orient_max, 1.0)],
        "marker.colorbar.title.text": ["orientation error (°)"],
    }  # fmt: skip
    styles = [("distance error", distance_style), ("orientation error", orientation_style)]
    targets = [points_index]
    if result.coverage is not None and len(result.coverage.state):
        # The in-spec map over the whole surface (walls too), in place of the scan points.
        fig.add_trace(_coverage_trace(result.coverage))
        targets = [points_index, points_index + 1]
        # Per-trace values: the map keeps its own colours (None) and is hidden again.
        styles = [
            (label, {**{k: v + [None] for k, v in style.items()}, "visible": [True, False]})
            for label, style in styles
        ]
    buttons = [
        {"label": label, "method": "restyle", "args": [style, targets]} for label, style in styles
    ]
    # The cell and the arm after the points and the map, whose indices the buttons name.
    if result.cell is not None:
        fig.add_traces(cell_traces(part, result.cell))
    if result.arm is not None:
        add_arm(fig, traj, result.arm)
    if len(targets) == 2:
        buttons.append(
            {"label": "in-spec map", "method": "restyle",
             "args": [{"visible": [False, True]}, targets]}
        )  # fmt: skip
    fig.update_layout(
        title=f"{result.name}: trajectory and simulated scan",
        height=620,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={"aspectmode": "data", "camera": {"eye": {"x": 1.3, "y": -1.3, "z": 1.0}}},
        legend={"x": 0, "y": 1},
        updatemenus=[{"type": "buttons", "direction": "right", "x": 0.32, "xanchor": "left",
                      "y": 1.08, "buttons": buttons}],
    )  # fmt: skip
    return fig


def _coverage_trace(coverage: CoverageMap):
    """The in-spec map over the whole surface to inspect (walls included, which a top-down
    map flattens): its samples coloured in spec / out of spec / not seen."""
    import plotly.graph_objects as go

    keep = _subsample(len(coverage.state), MAX_POINTS_PER_PLANNER)
    p, state = coverage.points_part[keep], coverage.state[keep]
    palette = np.array([COVERAGE_COLOURS[s][0] for s in SurfaceState])  # indexed by state
    colours = palette[state]
    return go.Scatter3d(
        x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", name="surface: in spec / out / not seen",
        marker={"size": 2.0, "color": colours}, visible=False, hoverinfo="skip",
    )  # fmt: skip


def _training_figure(log: dict[str, np.ndarray]):
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    x_key = "timesteps"
    x = log[x_key]
    # The paper's figures: episodic reward, episode length, reward per step, partial rewards.
    keys = [k for k in CURVES if k in log and np.isfinite(log[k]).any()]
    if not keys:
        keys = [k for k in log if k != x_key and np.isfinite(log[k]).any()]
    cols = 3
    rows = max(1, -(-len(keys) // cols))
    fig = make_subplots(rows=rows, cols=cols, subplot_titles=keys)
    for i, key in enumerate(keys):
        fig.add_trace(
            go.Scatter(x=x, y=log[key], mode="lines+markers", name=key, showlegend=False),
            row=i // cols + 1,
            col=i % cols + 1,
        )
    fig.update_layout(height=260 * rows, title="PPO training (the paper's training figures)")
    fig.update_xaxes(title_text=x_key or "update")
    return fig


def _png_data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode()


def _figure(path: Path) -> str:
    name = html.escape(path.name)
    return (
        f"<figure><img src='{_png_data_uri(path)}' alt='{name}'>"
        f"<figcaption>{name}</figcaption></figure>"
    )


_STYLE = """
body{font-family:system-ui,sans-serif;margin:24px auto;max-width:1400px;color:#222}
table{border-collapse:collapse;margin:12px 0}th,td{border:1px solid #ccc;padding:4px 10px}
td{text-align:right;font-variant-numeric:tabular-nums}tr:nth-child(even){background:#f6f6f6}
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(600px,1fr));gap:12px}
.grid>*{min-width:0}
img{max-width:100%;border:1px solid #ddd}.note{color:#555;font-size:0.9em}
.headline{font-size:1.3em;margin:8px 0 16px}
"""


def write_html_report(
    path: str | os.PathLike,
    part: Part,
    results: list[PlannerResult],
    sensor_name: str,
    training_log: Path | None = None,
    pictures: list[Path] | None = None,
    notes: list[str] | None = None,
) -> None:
    """Write the report atomically. `pictures` are PNGs embedded at the end (error maps)."""
    import plotly.io as pio

    if not results:
        raise ValueError("the report needs at least one planner result")
    finite = [np.abs(r.cloud.distance_error_mm) for r in results if len(r.cloud.points_part)]
    limit = float(np.percentile(np.concatenate(finite), 98)) if finite else 1.0
    limit = max(limit, 0.05)
    part_mesh = part_trace(part)
    figures = [_planner_figure(part, part_mesh, r, limit) for r in results]
    divs = [
        pio.to_html(f, full_html=False, include_plotlyjs=False, default_width="100%")
        for f in figures
    ]
    sections = [
        f"<h1>scanplan report — {html.escape(part.name)}</h1>",
        f"<p>part <b>{html.escape(part.name)}</b> "
        f"({' × '.join(f'{e:.0f}' for e in part.extents)} mm, {len(part.mesh.faces)} triangles),"
        f" sensor <b>{html.escape(sensor_name)}</b>.</p>",
    ]
    headline = _in_spec_headline(results)
    if headline:
        sections.append(headline)
    sections += ["<h2>Scan quality</h2>", metrics_table_html(results)]
    for key, what in (
        ("in_spec_definition", "In-spec coverage"),
        ("coverage_definition", "Coverage"),
    ):
        definition = lookup(results[0].metrics, (key,))
        if definition:
            sections.append(f"<p class='note'>{what}: {html.escape(str(definition))}</p>")
    for note in notes or []:
        sections.append(f"<p class='note'>{html.escape(note)}</p>")
    # The in-spec maps belong with the headline figure; the error maps come at the end.
    in_spec_maps = [p for p in pictures or [] if Path(p).name.startswith("in_spec")]
    pictures = [p for p in pictures or [] if p not in in_spec_maps]
    if in_spec_maps:
        sections.append("<h2>Where the surface is in spec</h2>")
        sections.extend(_figure(Path(p)) for p in in_spec_maps)
    sections.append("<h2>Trajectories and simulated scans</h2>")
    sections.append(
        "<p class='note'>Drag to rotate. Buttons switch the point colours between distance "
        "error (z_s − W_d) and orientation error (angle between the beam and the normal); "
        "cones show the laser axis along the path.</p>"
    )
    sections.extend(f"<div>{d}</div>" for d in divs)
    if training_log is not None and Path(training_log).is_file():
        log = read_log(training_log)
        if len(log["timesteps"]):
            sections.append("<h2>Training</h2>")
            sections.append(
                pio.to_html(_training_figure(log), full_html=False, include_plotlyjs=False)
            )
    if pictures:
        sections.append("<h2>Error maps and training curves</h2><div class='grid'>")
        sections.extend(_figure(Path(pic)) for pic in pictures)
        sections.append("</div>")
    atomic_write_text(path, _page(f"scanplan report — {part.name}", sections))


def _page(title: str, sections: list[str]) -> str:
    """One self-contained page: the sections under plotly.js, inlined once."""
    import plotly

    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style>"
        f"<script>{plotly.offline.get_plotlyjs()}</script></head><body>"
        + "\n".join(sections)
        + "</body></html>"
    )


def write_scene_page(
    path: str | os.PathLike, figure, title: str, notes: list[str] | None = None
) -> None:
    """Write the page of a plan's 3-D scene (`scene.scene_figure`) atomically, with `notes`
    (one paragraph each) under its title."""
    import plotly.io as pio

    div = pio.to_html(figure, full_html=False, include_plotlyjs=False, default_width="100%")
    sections = [f"<h1>{html.escape(title)}</h1>"]
    sections += [f"<p class='note'>{html.escape(note)}</p>" for note in notes or []]
    sections.append(f"<div>{div}</div>")
    atomic_write_text(path, _page(title, sections))
