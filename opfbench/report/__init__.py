"""The benchmark's HTML report: `write_report(run_dir, ...)` reads a run folder (and a
forecast and a fault folder when given) and writes one self-contained page."""

from opfbench.report.build import build_html, write_report

__all__ = ["build_html", "write_report"]
