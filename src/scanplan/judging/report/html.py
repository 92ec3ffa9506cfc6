"""The self-contained HTML report: interactive 3-D views (plotly), metrics, maps, training.

One file, plotly.js inlined once, PNGs embedded as data URIs, so it opens offline and can be
mailed as is. The metrics table is built from the same `to_json_dict()` the CLI prints.
By default the page is kept small (the demo's under 5 MB): plotly.js gzipped (the browser
unpacks it), the 3-D views decimated, the part's mesh sent once, large pictures downscaled;
`full_3d` keeps every face, sampled point and pixel.
"""

from __future__ import annotations

import base64
import gzip
import html
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanplan.core.files import atomic_write_text
from scanplan.core.trajectory import Trajectory
from scanplan.judging import CoverageMap, SurfaceState
from scanplan.judging.report.maps import COVERAGE_COLOURS
from scanplan.judging.report.scene import (
    MAX_PART_FACES,
    VIEW_COLOURS,
    ArmPoses,
    add_arm,
    cell_traces,
    part_trace,
    path_trace,
)
from scanplan.judging.report.table import lookup, table_rows, tolerance_label
from scanplan.judging.report.training import CURVES, read_log
from scanplan.sensor.cloud import PointCloud
from scanplan.world.cell import Cell
from scanplan.world.part import Part

# The compact page's 3-D budget per planner: enough for a smooth picture, small enough that
# the demo's page of three planners stays under 5 MB.
MAX_POINTS_PER_PLANNER = 10_000
MAX_PATH_POINTS = 3_000
MAX_ARROWS = 120
# Pictures larger than this are embedded downscaled to about twice a grid column's width
# (700 px on the 1400 px page, twice for sharp screens; 1280 keeps the door's three-planner
# page under 5 MB), as the smaller of a 256-colour PNG and a JPEG; the files keep every pixel.
PICTURE_MAX_BYTES = 300_000
PICTURE_MAX_WIDTH_PX = 1280


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
    """The headline figure, one per planner: the in-spec coverage and its tolerance, and the
    share of the visibility ceiling it reaches."""
    shown = []
    for r in results:
        v = lookup(r.metrics, ("in_spec_coverage",))
        if not isinstance(v, int | float):
            continue
        share, ceiling = (
            lookup(r.metrics, (k,)) for k in ("in_spec_of_ceiling", "visibility_ceiling")
        )
        of = (
            f" <span class='note'>({share:.1%} of the ceiling {ceiling:.1%})</span>"
            if isinstance(share, int | float) and isinstance(ceiling, int | float)
            else ""
        )
        shown.append(f"{html.escape(r.name)} <b>{v:.1%}</b>{of}")
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


def _subsample(n: int, k: int | None, seed: int = 0) -> np.ndarray:
    if k is None or n <= k:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=k, replace=False))


def _planner_figure(
    part: Part, part_mesh, result: PlannerResult, distance_limit_mm: float, full_3d: bool
):
    import plotly.graph_objects as go

    traj, cloud = result.trajectory, result.cloud
    pos = traj.positions_mm.astype(np.float32)
    max_path = None if full_3d else MAX_PATH_POINTS
    traces = [part_mesh]
    views = traj.meta.get("views") or []
    if len(views) > 1:
        # Each view's poses in its own colour (a view is a block of swaths), moves in grey.
        traces.append(path_trace(pos, ~traj.scanning, "moves", "gray", 2, max_path))
        for k, v in enumerate(views):
            in_view = (traj.swath >= v["first_swath"]) & (traj.swath <= v["last_swath"])
            axis = ", ".join(f"{c:.2f}" for c in v["axis"])
            colour = VIEW_COLOURS[k % len(VIEW_COLOURS)]
            keep = in_view & traj.scanning
            traces.append(path_trace(pos, keep, f"view {k} ({axis})", colour, 4, max_path))
    else:
        every = np.ones(len(pos), bool)
        traces.append(path_trace(pos, every, "sensor path", "black", 3, max_path))
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
    keep = _subsample(len(cloud.points_part), None if full_3d else MAX_POINTS_PER_PLANNER)
    p = cloud.points_part[keep].astype(np.float32)
    # Rounded: the buttons carry these as plain lists, a hundredth of a mm or degree shows.
    dist = np.round(cloud.distance_error_mm[keep], 2)
    orient = np.round(np.degrees(cloud.orientation_error_rad[keep]), 2)
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
        fig.add_trace(_coverage_trace(result.coverage, full_3d))
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


def _coverage_trace(coverage: CoverageMap, full_3d: bool):
    """The in-spec map over the whole surface to inspect (walls included, which a top-down
    map flattens): its samples coloured in spec / out of spec / not seen."""
    import plotly.graph_objects as go

    keep = _subsample(len(coverage.state), None if full_3d else MAX_POINTS_PER_PLANNER)
    p, state = coverage.points_part[keep].astype(np.float32), coverage.state[keep]
    # The state (one byte a sample) through a stepped colour scale, not a colour string each.
    palette = [COVERAGE_COLOURS[s][0] for s in SurfaceState]
    last = max(len(palette) - 1, 1)
    scale = [[bound / len(palette), c] for k, c in enumerate(palette) for bound in (k, k + 1)]
    return go.Scatter3d(
        x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", name="surface: in spec / out / not seen",
        marker={"size": 2.0, "color": state.astype(np.int8), "colorscale": scale, "cmin": -0.5,
                "cmax": last + 0.5, "showscale": False},
        visible=False, hoverinfo="skip",
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


def _picture_data_uri(path: Path, full: bool) -> str:
    """The picture as a data URI; a large one (unless `full`) downscaled and re-encoded."""
    data = path.read_bytes()
    if full or len(data) <= PICTURE_MAX_BYTES:
        return "data:image/png;base64," + base64.b64encode(data).decode()
    from PIL import Image  # matplotlib's dependency

    with Image.open(path) as image:
        rgba = image.convert("RGBA")
    flat = Image.new("RGB", rgba.size, "white")
    flat.paste(rgba, mask=rgba.getchannel("A"))  # transparency onto the page's white
    if flat.width > PICTURE_MAX_WIDTH_PX:
        height = round(flat.height * PICTURE_MAX_WIDTH_PX / flat.width)
        flat = flat.resize((PICTURE_MAX_WIDTH_PX, height), Image.Resampling.LANCZOS)
    encoded = []
    for mime, save in (
        ("image/png", lambda out: flat.quantize(256).save(out, "PNG", optimize=True)),
        ("image/jpeg", lambda out: flat.save(out, "JPEG", quality=85)),
    ):
        buffer = io.BytesIO()
        save(buffer)
        encoded.append((len(buffer.getvalue()), mime, buffer.getvalue()))
    _, mime, best = min(encoded)
    return f"data:{mime};base64," + base64.b64encode(best).decode()


def _figure(path: Path, full: bool = False) -> str:
    name = html.escape(path.name)
    return (
        f"<figure><img src='{_picture_data_uri(path, full)}' alt='{name}'>"
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
    full_3d: bool = False,
) -> None:
    """Write the report atomically. `pictures` are PNGs embedded at the end (error maps).
    full_3d: the 3-D views with every face of the part and every sampled point, pictures at
    full size and plotly.js as is (a page tens of MB for a large part)."""
    if not results:
        raise ValueError("the report needs at least one planner result")
    finite = [np.abs(r.cloud.distance_error_mm) for r in results if len(r.cloud.points_part)]
    limit = float(np.percentile(np.concatenate(finite), 98)) if finite else 1.0
    limit = max(limit, 0.05)
    part_mesh = part_trace(part, max_faces=None if full_3d else MAX_PART_FACES)
    figures = [_planner_figure(part, part_mesh, r, limit, full_3d) for r in results]
    # Every planner's view starts with the same part mesh: sent once, shared by the page.
    shared = [_lighter_trace(part_mesh)]
    divs = [_figure_html(f, f"planner-{k}", shared_first=True) for k, f in enumerate(figures)]
    faces = "" if full_3d else f", drawn with at most {MAX_PART_FACES} in the 3-D views"
    sections = [
        f"<h1>scanplan report — {html.escape(part.name)}</h1>",
        f"<p>part <b>{html.escape(part.name)}</b> "
        f"({' × '.join(f'{e:.0f}' for e in part.extents)} mm, {len(part.mesh.faces)} triangles"
        f"{faces}), sensor <b>{html.escape(sensor_name)}</b>.</p>",
    ]
    headline = _in_spec_headline(results)
    if headline:
        sections.append(headline)
    sections += ["<h2>Scan quality</h2>", metrics_table_html(results)]
    for key, what in (
        ("in_spec_definition", "In-spec coverage"),
        ("visibility_ceiling_definition", "Visibility ceiling"),
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
        sections.extend(_figure(Path(p), full_3d) for p in in_spec_maps)
    sections.append("<h2>Trajectories and simulated scans</h2>")
    shown = (
        "every sampled scan point"
        if full_3d
        else f"up to {MAX_POINTS_PER_PLANNER:,} scan points and surface samples per planner"
    )
    sections.append(
        "<p class='note'>Drag to rotate. Buttons switch the point colours between distance "
        "error (z_s − W_d) and orientation error (angle between the beam and the normal); "
        f"lines show the laser axis along the path. Shown: {shown}.</p>"
    )
    sections.extend(divs)
    if training_log is not None and Path(training_log).is_file():
        log = read_log(training_log)
        if len(log["timesteps"]):
            sections.append("<h2>Training</h2>")
            sections.append(_figure_html(_training_figure(log), "training"))
    if pictures:
        sections.append("<h2>Error maps and training curves</h2><div class='grid'>")
        sections.extend(_figure(Path(pic), full_3d) for pic in pictures)
        sections.append("</div>")
    text = _page(f"scanplan report — {part.name}", sections, shared, compress=not full_3d)
    atomic_write_text(path, text)


def _lighter_trace(trace) -> dict:
    """A trace as plotly JSON, its numeric arrays as typed arrays (`_typed`)."""
    return _typed(trace.to_plotly_json())


def _typed(value):
    """Numeric arrays, anywhere in `value`, as plotly.js typed-array specs (base64, not a
    decimal list): floats as float32 (well under a micrometre at a part's scale), integers in
    the smallest type that holds them."""
    if isinstance(value, dict):
        return {k: _typed(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_typed(v) for v in value]
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "iuf" or value.ndim != 1:
        return value
    if value.dtype.kind == "f":
        value = value.astype(np.float32)
    else:
        lo, hi = (int(value.min()), int(value.max())) if value.size else (0, 0)
        kinds = (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32)
        value = value.astype(
            next(t for t in kinds if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max)
        )
    code = {"f": "f", "u": "u", "i": "i"}[value.dtype.kind] + str(value.dtype.itemsize)
    return {"dtype": code, "bdata": base64.b64encode(value.tobytes()).decode()}


def _figure_html(figure, div_id: str, shared_first: bool = False) -> str:
    """A figure's place on the page and its data, drawn once plotly.js is loaded (`_page`);
    with `shared_first`, its first trace is the page's shared trace 0."""
    data = [_lighter_trace(t) for t in figure.data]
    if shared_first:
        data[0] = {"shared": 0}
    layout = figure.layout.to_plotly_json()
    height = int(layout.get("height") or 500)
    return (
        f"<div id='{div_id}' class='plot' style='width:100%;height:{height}px'></div>"
        f"<script type='application/json' data-figure='{div_id}'>"
        f"{_script_json({'data': data, 'layout': layout})}</script>"
    )


def _script_json(value) -> str:
    """JSON that can sit inside a <script> element ("</" would end it)."""
    from plotly.io.json import to_json_plotly

    return to_json_plotly(value).replace("</", "<\\/")


# Unpacks plotly.js where it came gzipped (DecompressionStream: Chrome 80, Firefox 113,
# Safari 16.4), then draws every figure, its shared traces put back in.
_LOADER = """
(async () => {
  const packed = document.getElementById('scanplan-plotly-gz');
  if (!window.Plotly && packed) {
    try {
      const bytes = Uint8Array.from(atob(packed.textContent.trim()), c => c.charCodeAt(0));
      const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
      const script = document.createElement('script');
      script.textContent = await new Response(stream).text();
      document.head.appendChild(script);
    } catch (error) {
      document.body.insertAdjacentHTML('afterbegin', "<p class='note'>This browser cannot " +
        "unpack the 3-D views (" + error + "); write the report with --full-3d.</p>");
      return;
    }
  }
  const sharedText = document.getElementById('scanplan-shared').textContent;
  for (const element of document.querySelectorAll('script[data-figure]')) {
    const figure = JSON.parse(element.textContent);
    const shared = JSON.parse(sharedText);  // each figure its own copy: plotly writes to it
    const data = figure.data.map(t => ('shared' in t ? shared[t.shared] : t));
    Plotly.newPlot(element.dataset.figure, data, figure.layout, {responsive: true});
  }
})();
"""


def _page(
    title: str, sections: list[str], shared: list[dict] | None = None, compress: bool = True
) -> str:
    """One self-contained page: the sections, plotly.js inlined once (gzipped if `compress`)
    and the loader that draws the figures (`_figure_html`) with the `shared` traces."""
    import plotly

    plotly_js = plotly.offline.get_plotlyjs()
    if compress:
        packed = base64.b64encode(gzip.compress(plotly_js.encode(), 9, mtime=0)).decode()
        library = (
            f"<script type='application/octet-stream' id='scanplan-plotly-gz'>{packed}</script>"
        )
        head_script = ""
    else:
        library, head_script = "", f"<script>{plotly_js}</script>"
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style>{head_script}</head><body>"
        + "\n".join(sections)
        + library
        + "<script type='application/json' id='scanplan-shared'>"
        + f"{_script_json(shared or [])}</script>"
        + f"<script>{_LOADER}</script></body></html>"
    )


def write_scene_page(
    path: str | os.PathLike, figure, title: str, notes: list[str] | None = None
) -> None:
    """Write the page of a plan's 3-D scene (`scene.scene_figure`) atomically, with `notes`
    (one paragraph each) under its title."""
    sections = [f"<h1>{html.escape(title)}</h1>"]
    sections += [f"<p class='note'>{html.escape(note)}</p>" for note in notes or []]
    sections.append(_figure_html(figure, "scene"))
    atomic_write_text(path, _page(title, sections))
