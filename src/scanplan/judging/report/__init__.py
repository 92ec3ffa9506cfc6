"""Reports of a scan: PNG maps and the metrics table (`maps`, `table`), the HTML report
(`html`; its figures in `figures`, its page in `page`) and the atomic report directory that
holds them (`writer.write_report`)."""

from scanplan.judging.report.writer import Evaluated, write_report

__all__ = ["Evaluated", "write_report"]
