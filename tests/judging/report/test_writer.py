"""The report directory (report.writer): a directory that holds no report is never replaced."""

from __future__ import annotations

import pytest


def test_report_refuses_to_replace_a_foreign_directory(tmp_path):
    from scanplan.core.files import atomic_directory
    from scanplan.judging.report.writer import is_report

    home = tmp_path / "home"
    home.mkdir()
    (home / "thesis.tex").write_text("years of work")
    with pytest.raises(ValueError, match="holds no scanplan output"):
        with atomic_directory(home, is_report):
            pass
    assert (home / "thesis.tex").read_text() == "years of work"
    # A report is replaced whole, and nothing is left beside it.
    report = tmp_path / "report"
    report.mkdir()
    (report / "metrics.json").write_text("{}")
    with atomic_directory(report, is_report) as tmp:
        (tmp / "report.html").write_text("new")
    assert sorted(p.name for p in report.iterdir()) == ["report.html"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home", "report"]
