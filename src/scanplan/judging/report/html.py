"""The self-contained HTML report: interactive 3-D views (plotly), metrics, maps, training.

One file, plotly.js inlined once, PNGs embedded as data URIs, so it opens offline and can be
mailed as is. The metrics table is built from the same `to_json_dict()` the CLI prints.
By default the page is kept small (the demo's under 5 MB): plotly.js gzipped (the browser
unpacks it), the 3-D views decimated, the part's mesh sent once, large pictures downscaled;
`full_3d` keeps every face, sampled point and pixel. Its figures: `figures`; its page: `page`.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scanplan.core.files import atomic_write_text
from scanplan.judging.report.figures import (
    MAX_POINTS_PER_PLANNER,
    PlannerResult,
    planner_figure,
    training_figure,
)
from scanplan.judging.report.findings import Finding
from scanplan.judging.report.page import figure_html, lighter_trace, page_html, picture_html
from scanplan.judging.report.scene import MAX_PART_FACES, part_trace
from scanplan.judging.report.table import lookup, table_rows, tolerance_label
from scanplan.judging.report.training import read_log
from scanplan.world.part import Part

# What the definitions carried in the JSON call by their keys, in words for the page.
_PLAIN = (
    ("`in_spec_radius_mm`", "the in-spec radius ({in_spec_radius_mm:.2f} mm)"),
    ("`coverage_radius_mm`", "the coverage radius ({coverage_radius_mm:.2f} mm)"),
    ("`in_spec_of_ceiling`", "the in-spec share of the ceiling"),
    ("(`surface`)", ""),
    ("(`tolerance`)", ""),
    ("|z_s - W_d| <= tol_d", "a distance from the stand-off within the distance tolerance"),
    ("alpha_i <= tol_alpha", "an angle between beam and normal within the angle tolerance"),
    ("within tol_alpha", "within the angle tolerance"),
    ("2 delta_s_opt", "twice the optimal spacing"),
    ("delta_s_opt", "the optimal spacing"),
    ("`top`", "top"),
    ("`hemisphere`", "hemisphere"),
    ("`roi`", "roi"),
)


def plain(text: str, metrics: dict) -> str:
    """A definition from the JSON in words: its keys named or given their values, no
    backticks."""
    for key, words in _PLAIN:
        if key in text:
            try:
                words = words.format(**metrics)
            except (KeyError, TypeError, ValueError):
                words = words.split(" (")[0]
            text = text.replace(key, words)
    return " ".join(text.replace("`", "").split())


def metrics_table_html(results: list[PlannerResult], diagnostics: bool | None = False) -> str:
    head = "".join(f"<th>{html.escape(r.name)}</th>" for r in results)
    rows = [
        f"<tr><th>{html.escape(label)}</th>" + "".join(f"<td>{v}</td>" for v in values) + "</tr>"
        for label, values in table_rows([r.metrics for r in results], diagnostics)
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


def write_html_report(
    path: str | os.PathLike,
    part: Part,
    results: list[PlannerResult],
    sensor_name: str,
    training_log: Path | None = None,
    pictures: list[Path] | None = None,
    notes: list[str] | None = None,
    full_3d: bool = False,
    findings: Sequence[Finding] = (),
) -> None:
    """Write the report atomically. `pictures` are PNGs embedded at the end (error maps;
    training curves, shown only where the training log is not drawn); `findings` (the
    verdicts, the program and its arm, robustness) come first, each under its heading.
    full_3d: the 3-D views with every face of the part and every sampled point, pictures at
    full size and plotly.js as is (a page tens of MB for a large part)."""
    if not results:
        raise ValueError("the report needs at least one planner result")
    finite = [np.abs(r.cloud.distance_error_mm) for r in results if len(r.cloud.points_part)]
    limit = float(np.percentile(np.concatenate(finite), 98)) if finite else 1.0
    limit = max(limit, 0.05)
    part_mesh = part_trace(part, max_faces=None if full_3d else MAX_PART_FACES)
    figures = [planner_figure(part, part_mesh, r, limit, full_3d) for r in results]
    # Every planner's view starts with the same part mesh: sent once, shared by the page.
    shared = [lighter_trace(part_mesh)]
    divs = [figure_html(f, f"planner-{k}", shared_first=True) for k, f in enumerate(figures)]
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
    sections += [f.to_html() for f in findings]
    sections += ["<h2>Scan quality</h2>", metrics_table_html(results)]
    for key, what in (
        ("in_spec_definition", "In-spec coverage"),
        ("visibility_ceiling_definition", "Visibility ceiling"),
        ("coverage_definition", "Coverage"),
    ):
        definition = lookup(results[0].metrics, (key,))
        if definition:
            words = plain(str(definition), results[0].metrics)
            sections.append(f"<p class='note'>{what}: {html.escape(words)}</p>")
    for note in notes or []:
        sections.append(f"<p class='note'>{html.escape(note)}</p>")
    # The in-spec maps belong with the headline figure; the error maps come at the end.
    in_spec_maps = [p for p in pictures or [] if Path(p).name.startswith("in_spec")]
    pictures = [p for p in pictures or [] if p not in in_spec_maps]
    if in_spec_maps:
        sections.append("<h2>Where the surface is in spec</h2>")
        sections.extend(picture_html(Path(p), full_3d) for p in in_spec_maps)
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
    curves = [p for p in pictures if Path(p).name.startswith("training")]
    pictures = [p for p in pictures if p not in curves]
    if pictures:
        sections.append("<h2>Error maps</h2><div class='grid'>")
        sections.extend(picture_html(Path(pic), full_3d) for pic in pictures)
        sections.append("</div>")
    sections += _diagnostics(results, training_log, curves, full_3d)
    text = page_html(f"scanplan report — {part.name}", sections, shared, compress=not full_3d)
    atomic_write_text(path, text)


def _diagnostics(
    results: list[PlannerResult], training_log: Path | None, curves: list[Path], full_3d: bool
) -> list[str]:
    """The learning's diagnostics, folded away: the RL reward terms per planner, and the
    training curves once (the log drawn, or else its pictures)."""
    inner = []
    rewards = metrics_table_html(results, diagnostics=True)
    if "<td>" in rewards:
        inner += ["<p class='note'>The reward the RL agent learns from, per step (0 is best; "
                  "distance, angle and spacing terms).</p>", rewards]  # fmt: skip
    log = (
        read_log(training_log)
        if training_log is not None and Path(training_log).is_file()
        else None
    )
    if log is not None and len(log["timesteps"]):
        inner.append(figure_html(training_figure(log), "training"))
    elif curves:
        inner += [picture_html(Path(p), full_3d) for p in curves]
    if not inner:
        return []
    return [
        "<details><summary>RL diagnostics: reward terms and training</summary>",
        *inner,
        "</details>",
    ]


def write_scene_page(
    path: str | os.PathLike, figure, title: str, notes: list[str] | None = None
) -> None:
    """Write the page of a plan's 3-D scene (`scene.scene_figure`) atomically, with `notes`
    (one paragraph each) under its title."""
    sections = [f"<h1>{html.escape(title)}</h1>"]
    sections += [f"<p class='note'>{html.escape(note)}</p>" for note in notes or []]
    sections.append(figure_html(figure, "scene"))
    atomic_write_text(path, page_html(title, sections))
