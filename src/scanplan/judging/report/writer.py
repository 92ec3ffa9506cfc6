"""`write_report`: one report directory — maps, metrics.json, metrics.md, report.html and any
extra files — written atomically, so a failing or interrupted run never leaves half a one."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from scanplan.core.files import atomic_directory, atomic_write_bytes, atomic_write_text
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import Metrics
from scanplan.world.part import Part

if TYPE_CHECKING:
    from scanplan.judging.report.figures import PlannerResult
    from scanplan.judging.report.findings import Finding
    from scanplan.judging.report.scene_arm import ArmPoses
    from scanplan.world.cell import Cell

# A directory holding one of these was written by scanplan and may be replaced.
_REPORT_MARKERS = ("metrics.json", "report.html")
DETECTABILITY_MAP_NAME = "detectability.png"


@dataclass(frozen=True)
class Evaluated:
    """One trajectory and its metrics, as a report shows them."""

    name: str
    trajectory: Trajectory
    metrics: Metrics


def is_report(path: Path) -> bool:
    """Whether a directory holds a scanplan report (one `write_report` may replace)."""
    return any((path / marker).exists() for marker in _REPORT_MARKERS)


def write_report(
    out_dir: str | os.PathLike,
    part: Part,
    results: Sequence[Evaluated],
    spec: ScanSpec,
    pictures: Sequence[Path] = (),
    notes: Sequence[str] = (),
    training_log: Path | None = None,
    files: Mapping[str, str | bytes | Path] | None = None,
    title: str | None = None,
    full_3d: bool = False,
    findings: Sequence[Finding] = (),
    later: Callable[[], tuple[Mapping[str, str | bytes | Path], Sequence[Finding]]] | None = None,
) -> Path:
    """Write the report directory of one or more evaluated trajectories; return report.html.

    One result: its maps (in-spec, distance, orientation) at the top level and metrics.json
    its metrics. Several: each one's maps in a sub-directory named after it, side-by-side
    comparison maps at the top level and metrics.json a mapping name -> metrics.
    pictures: more PNGs for the HTML report (e.g. training curves); files: more outputs by
    relative name — text, bytes, or a Path to copy. full_3d: report.html's 3-D views at full
    resolution (every face, every sampled point) and its pictures at full size; by default
    they are decimated so the page stays a few MB. findings: what the page tells first (the
    verdicts, the program and its arm, robustness), in plain words. later: called once the
    maps are drawn, for more files and findings still being made meanwhile (the demo's
    program, fitted in a second process)."""
    # Deferred: the HTML report draws with plotly and the arm (kinematics, FCL).
    from scanplan.judging.report.html import write_html_report

    if not results:
        raise ValueError("the report needs at least one evaluated trajectory")
    names = [r.name for r in results]
    if len(set(names)) != len(names):
        raise ValueError(f"report: trajectory names must differ, got {names}")
    out_dir = Path(out_dir)
    with atomic_directory(out_dir, is_report) as tmp:
        maps = _plot_maps(tmp, part, results)
        detectability = _plot_detectability(tmp, part, results)
        if detectability is not None:
            maps.append(detectability)
        files = dict(files or {})
        if later is not None:
            more_files, more_findings = later()
            files.update(more_files)
            findings = [*findings, *more_findings]
        _write_files(tmp, files)
        _write_metrics(tmp, part, results, title)
        notes = list(notes)
        with_cloud = _planner_results(part, results, notes)
        if with_cloud:
            write_html_report(
                tmp / "report.html",
                part,
                with_cloud,
                spec.sensor.name,
                training_log=training_log,
                pictures=[*maps, *pictures],
                notes=notes,
                full_3d=full_3d,
                findings=findings,
            )
    return out_dir / "report.html"


def _has_map(m: Metrics) -> bool:
    """Whether `m` holds an in-spec map to draw."""
    return m.coverage_map is not None and len(m.coverage_map.state) > 0


def _plot_maps(tmp: Path, part: Part, results: Sequence[Evaluated]) -> list[Path]:
    """Plot the maps into the report directory `tmp`; return those the HTML report shows:
    one result's own maps, or the side-by-side comparisons of several (each one's own maps
    in its sub-directory)."""
    # Deferred: the maps draw with matplotlib.
    from scanplan.judging.report.maps import (
        COVERAGE_MAP_NAME,
        plot_comparison,
        plot_coverage_comparison,
        plot_coverage_map,
        plot_error_maps,
    )

    maps: list[Path] = []
    if len(results) == 1:
        r = results[0]
        if _has_map(r.metrics):
            maps.append(plot_coverage_map(r.metrics, tmp / COVERAGE_MAP_NAME, r.name, part.name))
        maps += plot_error_maps(r.metrics, tmp, planner=r.name, part=part.name)
        return maps
    for r in results:
        if _has_map(r.metrics):
            plot_coverage_map(r.metrics, tmp / r.name / COVERAGE_MAP_NAME, r.name, part.name)
        plot_error_maps(r.metrics, tmp / r.name, planner=r.name, part=part.name)
    sources = [(r.name, r.metrics) for r in results]
    if all(_has_map(r.metrics) for r in results):
        maps.append(plot_coverage_comparison(sources, tmp / "in_spec_coverage_maps.png", part.name))
    for quantity in ("distance", "orientation"):
        path = tmp / f"{quantity}_error_maps.png"
        maps.append(plot_comparison(sources, quantity, path, part=part.name))
    return maps


def _plot_detectability(tmp: Path, part: Part, results: Sequence[Evaluated]) -> Path | None:
    """The detectability maps of the results that measured one, side by side in one
    picture; None when none did."""
    detectable = [
        (r.name, *found, (r.metrics.detectable or {}).get("type", "defect"))
        for r in results
        if (found := r.metrics.detectable_map) is not None
    ]
    if not detectable:
        return None
    # Deferred: as the maps.
    from scanplan.judging.report.pod import plot_detectability_maps

    return plot_detectability_maps(
        [d[:3] for d in detectable],
        "/".join(sorted({d[3] for d in detectable})),
        tmp / DETECTABILITY_MAP_NAME,
        part.name,
    )


def _write_files(tmp: Path, files: Mapping[str, str | bytes | Path]) -> None:
    """The caller's extra outputs by relative name: text, bytes, or a Path to copy."""
    for name, content in files.items():
        target = tmp / name
        if isinstance(content, Path):
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(content, target)
        else:
            atomic_write_bytes(
                target, content.encode("utf-8") if isinstance(content, str) else content
            )


def _write_metrics(tmp: Path, part: Part, results: Sequence[Evaluated], title: str | None) -> None:
    """metrics.json (one result's metrics, or a mapping name -> metrics) and metrics.md."""
    # Deferred: as the maps.
    from scanplan.judging.report.maps import metrics_table_markdown

    if len(results) == 1:
        data: dict = results[0].metrics.to_json_dict()
    else:
        data = {r.name: r.metrics.to_json_dict() for r in results}
    atomic_write_text(tmp / "metrics.json", json.dumps(data, indent=1, allow_nan=False) + "\n")
    atomic_write_text(
        tmp / "metrics.md",
        f"# {title or part.name}\n\n"
        + metrics_table_markdown([r.metrics for r in results], [r.name for r in results]),
    )


def _planner_results(
    part: Part, results: Sequence[Evaluated], notes: list[str]
) -> list[PlannerResult]:
    """What the HTML report shows of each result with a simulated scan to draw."""
    # Deferred: as the HTML report (write_report).
    from scanplan.judging.report.figures import PlannerResult

    return [
        PlannerResult(
            r.name,
            r.trajectory,
            cloud,
            r.metrics.to_json_dict(),
            r.metrics.coverage_map,
            *_scene(part, r, notes),
        )
        for r in results
        if (cloud := r.metrics.cloud) is not None and len(cloud.points_part)
    ]


def _scene(part: Part, result: Evaluated, notes: list[str]) -> tuple[Cell | None, ArmPoses | None]:
    """The cell and the arm the report draws with `result`'s path; where the plan's records
    no longer rebuild them (a fixture or arm file gone), a note says so and neither is drawn."""
    # Deferred: as in write_report (the arm loads the kinematics and FCL).
    from scanplan.judging.report.scene_arm import recorded_scene

    try:
        return recorded_scene(part, result.trajectory)
    except (ValueError, OSError) as exc:
        notes.append(f"{result.name}: the cell and the arm are not drawn ({exc})")
        return None, None
