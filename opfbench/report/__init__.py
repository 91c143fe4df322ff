"""The benchmark's HTML report: `write_report(run_dir, ...)` reads a run folder (and a
forecast and a fault folder when given) and writes one self-contained page. The heavy
parts (pandas, Plotly, Jinja2) load on first use, so importing the package stays light."""

from __future__ import annotations

__all__ = ["build_html", "write_report"]


def __getattr__(name: str):
    if name in __all__:
        from opfbench.report import build

        return getattr(build, name)
    raise AttributeError(f"module 'opfbench.report' has no attribute {name!r}")
