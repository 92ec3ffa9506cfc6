"""The plotly figures of the HTML report: one planner's 3-D view (its path, the laser axis,
its simulated scan, its in-spec map, the cell and the arm) and the training curves. plotly
is imported where a figure is drawn, so importing this module stays light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanplan.core.plan import view_records
from scanplan.core.trajectory import Trajectory
from scanplan.judging import CoverageMap, SurfaceState
from scanplan.judging.report.maps import COVERAGE_COLOURS
from scanplan.judging.report.scene import (
    add_arm,
    cell_traces,
    passes_traces,
    path_trace,
)
from scanplan.judging.report.scene_arm import ArmPoses
from scanplan.judging.report.training import CURVES
from scanplan.sensor.cloud import PointCloud
from scanplan.world.cell import Cell
from scanplan.world.part import Part

# The compact page's 3-D budget per planner: enough for a smooth picture, small enough that
# the demo's page of three planners stays under 5 MB.
MAX_POINTS_PER_PLANNER = 10_000
MAX_PATH_POINTS = 3_000
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


def _subsample(n: int, k: int | None, seed: int = 0) -> np.ndarray:
    if k is None or n <= k:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=k, replace=False))


def planner_figure(
    part: Part, part_mesh, result: PlannerResult, distance_limit_mm: float, full_3d: bool
):
    import plotly.graph_objects as go  # deferred: plotly loads only when a figure is drawn

    traj, cloud = result.trajectory, result.cloud
    pos = traj.positions_mm.astype(np.float32)
    max_path = None if full_3d else MAX_PATH_POINTS
    traces = [part_mesh]
    views = view_records(traj)
    if len(views) > 1:
        # The views grouped by the side they look from, as on the plan's 3-D page.
        traces += passes_traces(traj, max_path)
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
    import plotly.graph_objects as go  # deferred: plotly loads only when a figure is drawn

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


def training_figure(log: dict[str, np.ndarray]):
    import plotly.graph_objects as go  # deferred: plotly loads only when a figure is drawn
    from plotly.subplots import make_subplots  # deferred, as above

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
