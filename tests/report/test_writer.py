"""The report directory (report.writer): a directory that holds no report is never replaced."""

from __future__ import annotations

import pytest


def test_report_refuses_to_replace_a_foreign_directory(tmp_path):
    from scanplan.report import atomic_directory

    home = tmp_path / "home"
    home.mkdir()
    (home / "thesis.tex").write_text("years of work")
    with pytest.raises(ValueError, match="holds no scanplan report"):
        with atomic_directory(home):
            pass
    assert (home / "thesis.tex").read_text() == "years of work"
