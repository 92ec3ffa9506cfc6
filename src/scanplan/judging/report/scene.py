"""The 3-D scene of a plan, drawn without simulating it: the part lit and smooth-shaded, its
table and fixtures, the passes coloured by the side their view looks from, the moves between
them, and the arm (see-through) at a few poses of each pass with the poses it cannot fly
marked. Plotly traces only; `html` puts them in a page.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scanplan.core.plan import view_of_pose, view_records
from scanplan.core.trajectory import Trajectory
from scanplan.judging.report.scene_arm import ArmPoses, pass_runs
from scanplan.judging.report.scene_axes import (
    CAPSULE_SIDES,
    axes_traces,
    capsule_mesh,
)
from scanplan.judging.report.view_groups import group_label, groups, view_name
from scanplan.world.cell import Cell
from scanplan.world.part import Part

# Enough for a smooth picture, small enough that the page stays a few MB.
MAX_PART_FACES = 15_000
MAX_PATH_POINTS = 20_000
# One colour per side the views look from (plotly's D3 palette).
VIEW_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
                "#7f7f7f", "#bcbd22", "#17becf")  # fmt: skip
ARM_COLOUR = "#6b6b6b"
# See-through, so the part and the passes show through the arm.
ARM_OPACITY = 0.35
# A grey part lit from above and in front: relief (a boss, a hole) shows by its shading.
PART_LIGHTING = {"ambient": 0.35, "diffuse": 0.85, "specular": 0.25, "roughness": 0.6,
                 "fresnel": 0.1}  # fmt: skip
PART_LIGHT_POSITION = {"x": 3e4, "y": -6e4, "z": 1e5}  # plotly caps each at 1e5
PROBLEM_COLOUR = "#e6001a"
MOVE_COLOUR = "#a0a0a0"
# The table is drawn as a slab this deep, not its whole block (a metre deep), which would
# dwarf the part and the arm.
TABLE_SLAB_MM = 30.0


def part_trace(
    part: Part,
    name: str = "part",
    colour: str = "lightgray",
    opacity: float = 0.45,
    max_faces: int | None = MAX_PART_FACES,
    **kwargs: Any,
):
    """The part's mesh, decimated to `max_faces` if larger (None: every face), lit and
    smooth-shaded: vertices split at edges sharper than 30° (trimesh's smooth_shaded), so
    curved faces shade smoothly and edges stay crisp."""
    import plotly.graph_objects as go

    mesh = part.mesh
    if max_faces is not None and len(mesh.faces) > max_faces:
        try:
            mesh = mesh.simplify_quadric_decimation(face_count=max_faces)
        except (ImportError, ValueError):  # decimation is cosmetic: fall back to the full mesh
            mesh = part.mesh
    mesh = mesh.smooth_shaded
    v, f = mesh.vertices, mesh.faces
    return go.Mesh3d(
        x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2],
        color=colour, opacity=opacity, name=name, hoverinfo="skip", flatshading=False,
        lighting=PART_LIGHTING, lightposition=PART_LIGHT_POSITION, showlegend=True, **kwargs,
    )  # fmt: skip


def path_trace(
    pos: np.ndarray,
    keep: np.ndarray,
    name: str,
    colour: str,
    width: int,
    max_points: int | None = None,
    **kwargs: Any,
):
    """The poses where `keep` as one line, broken (NaN rows) wherever `keep` is False; each
    run thinned to about `max_points` in all (its ends kept)."""
    import plotly.graph_objects as go

    idx = np.flatnonzero(keep)
    step = 1 if max_points is None else max(1, -(-len(idx) // max_points))
    breaks = np.flatnonzero(np.diff(idx) > 1)
    runs = np.split(idx, breaks + 1) if len(idx) else []
    pieces = []
    for run in runs:
        take = run[::step] if run[-1] in run[::step] else np.r_[run[::step], run[-1]]
        pieces += [pos[take], np.full((1, 3), np.nan)]
    line = np.concatenate(pieces) if pieces else np.zeros((0, 3))
    return go.Scatter3d(
        x=line[:, 0], y=line[:, 1], z=line[:, 2], mode="lines", connectgaps=False,
        line={"color": colour, "width": width}, name=name, **kwargs,
    )  # fmt: skip


def view_label(traj: Trajectory, k: int) -> str:
    views = view_records(traj)
    if len(views) <= 1:
        return "passes"
    return f"view {k}: {view_name(views[k].axis)}"


def passes_traces(traj: Trajectory, max_points: int | None = None) -> list:
    """The passes, one trace per view, coloured and grouped in the legend by the side they
    look from (one entry per side: at most five), and the moves between them in grey."""
    pos = traj.positions_mm
    view = view_of_pose(traj)
    axes = [v.axis for v in view_records(traj)] or [(0.0, 0.0, 1.0)]
    traces = [path_trace(pos, ~traj.scanning, "moves", MOVE_COLOUR, 2, max_points)]
    flown = [k for k in range(len(axes)) if (traj.scanning & (view == k)).any()]  # not given up
    for g, (where, members) in enumerate(groups([axes[k] for k in flown]).items()):
        views = [flown[m] for m in members]
        label = (
            view_label(traj, 0) if len(axes) == 1
            else group_label(where, axes, views)
        )  # fmt: skip
        for n, k in enumerate(views):
            traces.append(
                path_trace(
                    pos, traj.scanning & (view == k), label if n == 0 else view_label(traj, k),
                    VIEW_COLOURS[g % len(VIEW_COLOURS)], 4, max_points, legendgroup=where,
                    showlegend=n == 0,
                )
            )  # fmt: skip
    return traces


def _box_mesh(lo: np.ndarray, hi: np.ndarray, name: str, colour: str, opacity: float):
    import plotly.graph_objects as go

    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=bool)
    v = np.where(corners, hi, lo)
    # Two triangles per face of the cube, vertices indexed as x*4 + y*2 + z.
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])  # fmt: skip
    return go.Mesh3d(
        x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2], color=colour,
        opacity=opacity, name=name, hoverinfo="name", flatshading=True, showlegend=True,
    )  # fmt: skip


def cell_traces(part: Part, cell: Cell) -> list:
    """The table (a slab of its block under the part and fixtures) and the fixtures."""
    traces = []
    block = cell.table_block(part)
    if block is not None:
        lo, hi = block[0].copy(), block[1]
        lo[2] = hi[2] - TABLE_SLAB_MM
        traces.append(_box_mesh(lo, hi, "table", "#c8a165", 0.6))
    for k, fixture in enumerate(cell.fixtures):  # one legend entry for them all
        traces.append(
            part_trace(fixture, f"fixtures ({len(cell.fixtures)})" if k == 0 else f"fixture {k}",
                       "#5b6f80", 0.8, legendgroup="fixtures", showlegend=k == 0)
        )  # fmt: skip
    return traces


def _arm_mesh(capsules: np.ndarray, radii: np.ndarray, name: str, colour: str, **kwargs: Any):
    import plotly.graph_objects as go

    v, f = capsule_mesh(capsules.reshape(-1, 2, 3), np.tile(radii, len(capsules)))
    return go.Mesh3d(
        x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2], color=colour,
        opacity=ARM_OPACITY, name=name, hoverinfo="name", flatshading=False,
        lighting={"ambient": 0.55, "diffuse": 0.7, "specular": 0.2}, legendgroup="arm",
        **{"showlegend": False, **kwargs},
    )  # fmt: skip


def _markers(pos: np.ndarray, name: str, colour: str, symbol: str, size: int, **kwargs: Any):
    import plotly.graph_objects as go

    return go.Scatter3d(
        x=pos[:, 0], y=pos[:, 1], z=pos[:, 2], name=name,
        marker={"color": colour, "symbol": symbol, "size": size}, **{"mode": "markers", **kwargs},
    )  # fmt: skip


def add_arm(fig, traj: Trajectory, arm: ArmPoses) -> None:
    """Add the arm to `fig`: at each shown pose (a slider steps through them, its first step
    shows them all; those whose links collide in red), markers on the poses it cannot fly,
    and its base."""
    view = view_of_pose(traj)
    runs = pass_runs(traj)
    pass_of = np.full(len(traj), -1)
    for p, run in enumerate(runs):
        pass_of[run] = p
    first = len(fig.data)
    labels = []
    for j, i in enumerate(arm.shown):
        run = runs[pass_of[i]] if pass_of[i] >= 0 else np.array([i])
        where = "first" if i == run[0] else "last" if i == run[-1] else "middle"
        setting = ""
        if arm.axes is not None and arm.shown_axes is not None:
            setting = ", " + ", ".join(
                f"{n.rsplit('_', 1)[0]} {v:.0f} {n.rsplit('_', 1)[1]}"
                for n, v in zip(arm.axes.names, arm.shown_axes[j], strict=True)
            )
        labels.append(f"pose {i} (view {view[i]}, pass {pass_of[i]}, {where}{setting})")
        bad = bool(arm.colliding[i])
        fig.add_trace(
            _arm_mesh(
                arm.capsules_part[[j]], arm.radii,
                f"{arm.robot} at {labels[-1]}" + (": links collide" if bad else ""),
                PROBLEM_COLOUR if bad else ARM_COLOUR, visible=j == 0,
            )
        )  # fmt: skip
    m = len(arm.shown)
    if m:
        colour = np.where(arm.colliding[arm.shown], PROBLEM_COLOUR, ARM_COLOUR)
        fig.add_trace(
            _arm_mesh(
                arm.capsules_part, arm.radii, f"{arm.robot} at {m} poses", ARM_COLOUR,
                visible=False, facecolor=np.repeat(colour, len(arm.radii) * 4 * CAPSULE_SIDES),
            )
        )  # fmt: skip
        steps = [
            {
                "label": f"all {m} poses",
                "method": "restyle",
                "args": [{"visible": [False] * m + [True]}, list(range(first, first + m + 1))],
            }
        ]
        for j, label in enumerate(labels):
            visible = [k == j for k in range(m + 1)]
            steps.append(
                {"label": label, "method": "restyle",
                 "args": [{"visible": visible}, list(range(first, first + m + 1))]}
            )  # fmt: skip
        fig.update_layout(
            sliders=[{
                "active": 1, "steps": steps, "x": 0.05, "len": 0.9, "y": 0, "yanchor": "top",
                "pad": {"t": 10, "b": 10}, "font": {"color": "rgba(0,0,0,0)"},
                "currentvalue": {"prefix": f"{arm.robot} at ", "font": {"color": "#222"}},
            }]
        )  # fmt: skip
    pos = traj.positions_mm
    for mask, what, symbol in (
        (arm.unreachable, "unreachable or beyond joint limits", "x"),
        (arm.colliding, "a link collides", "diamond-open"),
    ):
        if mask.any():
            fig.add_trace(
                _markers(pos[mask], f"{int(mask.sum())} poses: {what}", PROBLEM_COLOUR, symbol,
                         4, hoverinfo="name")
            )  # fmt: skip
    base = arm.base_part
    # The column from the base up to the first link: where the arm stands.
    top = arm.capsules_part[0, 0, 0] if m else base
    fig.add_trace(
        # Always shown, so the legend entry that hides and shows the whole arm.
        go_line(np.array([base, top]), f"{arm.robot} arm", ARM_COLOUR, 14,
                mode="lines+markers+text", text=[f"{arm.robot} base", ""], legendgroup="arm",
                textposition="bottom center",
                marker={"symbol": "square", "size": 6, "color": "black"})
    )  # fmt: skip


def go_line(points: np.ndarray, name: str, colour: str, width: int, **kwargs: Any):
    """A polyline through `points` (p, 3)."""
    import plotly.graph_objects as go

    return go.Scatter3d(
        x=points[:, 0], y=points[:, 1], z=points[:, 2], name=name,
        line={"color": colour, "width": width}, **{"mode": "lines", **kwargs},
    )  # fmt: skip


def scene_figure(
    part: Part,
    traj: Trajectory,
    cell: Cell | None = None,
    arm: ArmPoses | None = None,
    title: str = "",
    max_points: int | None = MAX_PATH_POINTS,
):
    """The plan's 3-D scene as a plotly Figure."""
    import plotly.graph_objects as go

    traces = [part_trace(part, colour="#8c99a6", opacity=1.0)]
    if cell is not None:
        traces += cell_traces(part, cell)
    traces += passes_traces(traj, max_points)
    if arm is not None:
        traces += axes_traces(arm.axes, arm.shown_axes, arm.T_base_part)
    fig = go.Figure(traces)
    if arm is not None:
        add_arm(fig, traj, arm)
    fig.update_layout(
        title=title,
        height=860,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={
            "aspectmode": "data",
            "camera": {"eye": {"x": 1.3, "y": -1.3, "z": 0.9}},
            "xaxis": {"title": "x (mm)"},
            "yaxis": {"title": "y (mm)"},
            "zaxis": {"title": "z (mm)"},
        },
        legend={"x": 0, "y": 1},
    )
    return fig
