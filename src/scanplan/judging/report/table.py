"""The metrics table, defined once: the CLI's printed table, the Markdown file and the HTML
report all show these rows, formatted the same way, from `Metrics.to_json_dict()`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

# (label, key path in Metrics.to_json_dict(), format). In-spec coverage is the headline.
TABLE_ROWS: list[tuple[str, tuple[str, ...], str]] = [
    ("in-spec coverage", ("in_spec_coverage",), "{:.1%}"),
    # No plan exceeds the ceiling: the gap to it, not to 100 %, is what planning can win.
    ("in-spec share of the visibility ceiling", ("in_spec_of_ceiling",), "{:.1%}"),
    ("visibility ceiling (some beam within tolerance)", ("visibility_ceiling",), "{:.1%}"),
    ("coverage (any valid point)", ("coverage_fraction",), "{:.1%}"),
    # Predicted from the scan's density and noise (`metrics.detectability`), no injection.
    ("dent found at 90 %, predicted (mm)", ("detectable", "a90_mm"), "{:.3f}"),
    ("profiles", ("profiles",), "{:.0f}"),
    ("mean |distance error| (mm)", ("distance_error_mm", "mean_abs"), "{:.3f}"),
    ("RMS distance error (mm)", ("distance_error_mm", "rms"), "{:.3f}"),
    ("p95 |distance error| (mm)", ("distance_error_mm", "p95_abs"), "{:.3f}"),
    ("mean per-profile |distance error| (mm)", ("distance_error_mm", "profile_mean_abs"), "{:.3f}"),
    ("mean orientation error (°)", ("orientation_error_deg", "mean"), "{:.2f}"),
    ("p95 orientation error (°)", ("orientation_error_deg", "p95"), "{:.2f}"),
    ("points in range", ("in_range_fraction",), "{:.1%}"),
    ("valid points", ("valid_fraction",), "{:.1%}"),
    ("mean spacing Δs (mm)", ("spacing_mm", "mean"), "{:.3f}"),
    ("spacing CV", ("spacing_mm", "cv"), "{:.3f}"),
    ("largest gap (mm)", ("spacing_mm", "max_gap"), "{:.2f}"),
    ("backward steps", ("spacing_mm", "backward_steps"), "{:.0f}"),
    ("path length (mm)", ("path_length_mm",), "{:.0f}"),
    ("cycle time (s)", ("cycle_time_s",), "{:.1f}"),
    ("colliding poses (within clearance)", ("collisions", "count"), "{:.0f}"),
    ("plan time (s)", ("plan_time_s",), "{:.2f}"),
    ("mean reward", ("reward", "mean"), "{:.4f}"),
    ("R_D", ("reward", "r_d"), "{:.4f}"),
    ("R_α", ("reward", "r_alpha"), "{:.4f}"),
    ("R_Δs", ("reward", "r_delta_s"), "{:.4f}"),
]
MISSING = "–"
# The learning's diagnostics (the RL reward terms): the report folds them away, as they
# mean little to whoever judges the scan.
DIAGNOSTIC_ROWS = {path for _, path, _ in TABLE_ROWS if path[0] == "reward"}
# The tolerance the in-spec row was judged with, appended to its label.
_TOLERANCE_LABEL = " (±{mm:g} mm, {deg:g}°)"


def lookup(metrics: dict[str, Any], path: tuple[str, ...]) -> Any:
    """The value at `path`, or None where a dictionary lacks it."""
    value: Any = metrics
    for key in path:
        if not isinstance(value, dict) or key not in value:
            return None
        value = value[key]
    return value


def table_rows(
    metrics: Sequence[dict[str, Any]], diagnostics: bool | None = None
) -> list[tuple[str, list[str]]]:
    """(label, formatted value per trajectory) for every row at least one trajectory has;
    only the diagnostic rows (`DIAGNOSTIC_ROWS`) with diagnostics True, none with False."""
    rows = []
    for label, path, fmt in TABLE_ROWS:
        if diagnostics is not None and (path in DIAGNOSTIC_ROWS) != diagnostics:
            continue
        values = [lookup(m, path) for m in metrics]
        if all(v is None for v in values):
            continue
        if path == ("in_spec_coverage",):
            label += tolerance_label(metrics) + surface_label(metrics)
        if path == ("cycle_time_s",):
            label += cycle_label(metrics)
        rows.append(
            (label, [fmt.format(v) if isinstance(v, int | float) else MISSING for v in values])
        )
    return rows


def surface_label(metrics: Sequence[dict[str, Any]]) -> str:
    """' of the top surface, 98 690 mm²': the surface every column was judged on (a
    comparison judges all on one; if they differ, the label says so rather than hide it)."""
    surfaces = {
        (s.get("name"), round(s.get("area_mm2") or 0.0))
        for m in metrics
        if isinstance(s := lookup(m, ("surface",)), dict)
    }
    if not surfaces:
        return ""
    if len(surfaces) > 1:
        return " (on different surfaces: " + ", ".join(sorted(f"{n}" for n, _ in surfaces)) + ")"
    name, area = surfaces.pop()
    digits = f"{area:,}".replace(",", " ")  # 181 206: grouped by spaces, as in the README
    return f" of the {name} surface, {digits} mm²"


def tolerance_label(metrics: Sequence[dict[str, Any]]) -> str:
    """' (±12.5 mm, 15°)': the in-spec tolerance of the first trajectory that has one."""
    for m in metrics:
        tol = lookup(m, ("tolerance",))
        if isinstance(tol, dict) and tol.get("mm") is not None and tol.get("deg") is not None:
            return _TOLERANCE_LABEL.format(mm=round(tol["mm"], 3), deg=round(tol["deg"], 3))
    return ""


def cycle_label(metrics: Sequence[dict[str, Any]]) -> str:
    """' (trapezoidal, kr6-r900 limits)': the arm whose limits timed the cycle."""
    names = sorted(
        {n for m in metrics if isinstance(n := lookup(m, ("cycle_time", "limits", "name")), str)}
    )
    return f" (trapezoidal, {', '.join(names)} limits)" if names else ""
