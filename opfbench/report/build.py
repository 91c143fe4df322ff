"""Build the benchmark's HTML report: one self-contained page (inline CSS and plotly.js,
figures as inline JSON; no request leaves the page) from the files of a run folder, and
optionally a forecast folder and a fault folder."""

from __future__ import annotations

from pathlib import Path

from opfbench.jsonio import write_atomic
from opfbench.report.inputs import Inputs, load_inputs
from opfbench.report.page import render
from opfbench.report.sections import all_sections, price_of


def build_html(inputs: Inputs, price: float | None = None) -> str:
    """The report page for `inputs` (see `opfbench.report.sections`)."""
    cost = price_of(inputs, price)
    cases = ", ".join(sorted(str(c) for c in (inputs.manifest or {}).get("config", {}).get("cases", [])))
    subtitle = f"Run folder {inputs.run_dir}" + (f" — case {cases}" if cases else "")
    return render("report.html.j2", "opfbench benchmark report", subtitle, plots=True, sections=all_sections(inputs, cost))


def write_report(
    run_dir: str | Path,
    forecast_dir: str | Path | None = None,
    fault_dir: str | Path | None = None,
    out: str | Path | None = None,
    price: float | None = None,
    year_dir: str | Path | None = None,
) -> Path:
    """Write the report of `run_dir` to `out` (default `run_dir/report.html`), atomically.

    `forecast_dir`: a forecast run's folder (default: the committed docs/forecast JSONs);
    `fault_dir`: a fault study's folder (default: none — the section says how to make one);
    `year_dir`: a year run's folder (default: the committed docs/year summary);
    `price`: energy price per kWh (default: the manifest's config.price_per_kwh)."""
    inputs = load_inputs(run_dir, forecast_dir, fault_dir, year_dir)
    target = Path(out) if out is not None else Path(run_dir) / "report.html"
    target.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(target, build_html(inputs, price))
    return target
