"""The table of a comparison, one row a part (and planner, views, arm), hardest first, as
the terminal, Markdown, CSV, JSON and an HTML page show it: the same figures under the same
names (`verdict.FIGURES`) in every format.
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from scanplan.judging.verdict import FIGURES, Verdict

# The columns a comparison shows, in order, where some row measured them.
COLUMNS = ("in-spec", "ceiling", "arm-cost", "cycle", "p5", "a90", "pod-a90")
FORMATS = ("text", "md", "csv", "json", "html")


@dataclass(frozen=True)
class Row:
    """One part planned one way: its names, its figures by `FIGURES` key, its verdicts, the
    plan file it was judged from and what plan noted; or the one-line error it failed with."""

    part: str
    planner: str
    views: str
    robot: str = ""
    figures: Mapping[str, float | None] = field(default_factory=dict)
    verdicts: tuple[Verdict, ...] = ()
    plan_file: str = ""
    notes: tuple[str, ...] = ()
    error: str | None = None

    @property
    def failed(self) -> bool:
        return any(not v.passed for v in self.verdicts)

    def verdict(self) -> str:
        if self.error is not None:
            return "error"
        if not self.verdicts:
            return ""
        failed = [v.criterion.text for v in self.verdicts if not v.passed]
        return "FAIL " + ", ".join(failed) if failed else "pass"

    def summary(self) -> str:
        if self.error is not None:
            return f"error: {self.error}"
        shown = [f"{k} {FIGURES[k].show(self.figures[k])}" for k in COLUMNS if k in self.figures]
        return ", ".join(shown) + (f" | {self.verdict()}" if self.verdicts else "")

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "part": self.part,
            "planner": self.planner,
            "views": self.views,
            "robot": self.robot or None,
            "plan_file": self.plan_file or None,
            "figures": {k: _finite(v) for k, v in self.figures.items()},
            "verdicts": [v.to_json_dict() for v in self.verdicts],
            "pass": None if not self.verdicts or self.error else not self.failed,
            "notes": list(self.notes),
            "error": self.error,
        }


def _finite(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def hardest_first(rows: Sequence[Row]) -> list[Row]:
    """Errors first, then the rows that fail their criteria, then by in-spec coverage (then
    p5) from the lowest: the parts hardest to scan at the top."""

    def key(row: Row) -> tuple:
        f = row.figures
        return (
            row.error is None,
            not row.failed,
            _finite(f.get("in-spec")) or 0.0,
            _finite(f.get("p5")) or 0.0,
            row.part,
        )

    return sorted(rows, key=key)


def columns(rows: Sequence[Row]) -> list[str]:
    """The figures some row measured, in `COLUMNS` order."""
    return [k for k in COLUMNS if any(k in r.figures for r in rows)]


def _cells(row: Row, keys: Sequence[str], raw: bool) -> list[str]:
    head = [row.part, row.planner, row.views] + ([row.robot] if raw else [])
    if row.error is not None:
        return (
            head + ["" for _ in keys] + (["error", row.error] if raw else [f"error: {row.error}"])
        )
    values = [row.figures.get(k) for k in keys]
    shown = [
        ("" if _finite(v) is None else f"{v:.6g}") if raw else FIGURES[k].show(v)
        for k, v in zip(keys, values, strict=True)
    ]
    return head + shown + ([row.verdict(), ""] if raw else [row.verdict()])


def _header(keys: Sequence[str], raw: bool) -> list[str]:
    names = list(keys) if raw else [_short(k) for k in keys]
    extra = ["verdict", "error"] if raw else ["verdict"]
    return ["part", "planner", "views", *(["robot"] if raw else []), *names, *extra]


def _short(key: str) -> str:
    return {"arm-cost": "arm cost", "a90": "dent a90", "pod-a90": "dent a90 (trials)"}.get(key, key)


def to_text(rows: Sequence[Row]) -> str:
    """An aligned table for the terminal, and a legend of the figures it names."""
    keys = columns(rows)
    table = [_header(keys, False), *(_cells(r, keys, False) for r in rows)]
    widths = [max(len(line[i]) for line in table) for i in range(len(table[0]))]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip() for line in table
    ]
    return "\n".join(lines + ["", *legend(keys)]) + "\n"


def legend(keys: Sequence[str]) -> list[str]:
    return [f"{_short(k)}: {FIGURES[k].label}" for k in keys]


def to_markdown(rows: Sequence[Row], title: str = "Comparison") -> str:
    keys = columns(rows)
    header = _header(keys, False)
    lines = [f"# {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        lines.append("| " + " | ".join(c.replace("|", "/") for c in _cells(r, keys, False)) + " |")
    return "\n".join([*lines, "", *(f"- {line}" for line in legend(keys))]) + "\n"


def to_csv(rows: Sequence[Row]) -> str:
    """Raw values: fractions as fractions, times in s, depths in mm (the JSON's units)."""
    keys = columns(rows)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(_header(keys, True))
    writer.writerows(_cells(r, keys, True) for r in rows)
    return out.getvalue()


def to_json(rows: Sequence[Row], options: Mapping[str, Any]) -> str:
    data = {
        "options": dict(options),
        "figures": {k: {"label": FIGURES[k].label, "unit": FIGURES[k].unit} for k in columns(rows)},
        "rows": [r.to_json_dict() for r in rows],
    }
    return json.dumps(data, indent=1, allow_nan=False) + "\n"


def to_html(rows: Sequence[Row], title: str = "Comparison") -> str:
    """A small self-contained page: the table, failing cells marked, and the legend."""
    keys = columns(rows)
    head = "".join(f"<th>{html.escape(h)}</th>" for h in _header(keys, False))
    body = []
    for r in rows:
        failing = {v.criterion.figure.key for v in r.verdicts if not v.passed}
        cells = _cells(r, keys, False)
        tds = []
        for i, cell in enumerate(cells):
            key = keys[i - 3] if 3 <= i < 3 + len(keys) else None
            bad = key in failing or (i == len(cells) - 1 and (r.failed or r.error))
            tds.append(f"<td{' class=fail' if bad else ''}>{html.escape(cell)}</td>")
        body.append("<tr>" + "".join(tds) + "</tr>")
    items = "".join(f"<li>{html.escape(line)}</li>" for line in legend(keys))
    style = (
        "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:4px 8px;text-align:right}"
        "td:nth-child(-n+3),th{text-align:left}.fail{background:#fdd;color:#900}"
    )
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{style}</style></head><body><h1>{html.escape(title)}</h1>"
        f"<p>Hardest to scan first.</p><table><tr>{head}</tr>{''.join(body)}</table>"
        f"<ul>{items}</ul></body></html>\n"
    )


def render(rows: Sequence[Row], fmt: str, options: Mapping[str, Any]) -> str:
    """The table in `fmt` (one of `FORMATS`)."""
    if fmt == "text":
        return to_text(rows)
    if fmt == "md":
        return to_markdown(rows)
    if fmt == "csv":
        return to_csv(rows)
    if fmt == "json":
        return to_json(rows, options)
    return to_html(rows)
