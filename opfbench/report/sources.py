"""Which forecast, fault and year-run folders the report reads (light: pathlib and json).

`opfbench run` and `opfbench report` use the same rule, so a rebuild gives the same page:
a folder given on the command line is used; otherwise `reports/forecast`, `reports/fault`
and `reports/year` are used when they hold a forecast run's metrics, a fault study's table
or a year run's summary. Without a forecast or year folder the report reads the committed
docs/forecast metrics and docs/year summary."""

from __future__ import annotations

import json
from pathlib import Path

from opfbench.errors import InputError

DEFAULT_FORECAST_DIR = Path("reports/forecast")
DEFAULT_FAULT_DIR = Path("reports/fault")
DEFAULT_YEAR_DIR = Path("reports/year")


def holds_forecasts(folder: Path) -> bool:
    return any((folder / f"forecast_{d}.json").is_file() for d in ("pv", "wind"))


def holds_fault_study(folder: Path) -> bool:
    return (folder / "fault.parquet").is_file()


def holds_year_run(folder: Path) -> bool:
    """A finished `opfbench run --period year` folder: its manifest and summary."""
    try:
        manifest = json.loads((folder / "manifest.json").read_text())
    except (OSError, ValueError):
        return False
    return manifest.get("config", {}).get("period") == "year" and (folder / "summary.csv").is_file()


def check_year_dir(folder: Path | None) -> None:
    """A `--year-dir` given on the command line must hold a finished year run."""
    if folder is not None and not holds_year_run(folder):
        raise InputError(
            f"--year-dir {folder} holds no finished year run (manifest.json with period 'year' and "
            f"summary.csv); write one with `opfbench run --period year --out {folder}`"
        )


def report_sources(
    forecast_dir: Path | None, fault_dir: Path | None, year_dir: Path | None = None
) -> tuple[Path | None, Path | None, Path | None]:
    """(forecast, fault, year-run folder) the report reads: as given, else the defaults when they hold data."""
    if forecast_dir is None and holds_forecasts(DEFAULT_FORECAST_DIR):
        forecast_dir = DEFAULT_FORECAST_DIR
    if fault_dir is None and holds_fault_study(DEFAULT_FAULT_DIR):
        fault_dir = DEFAULT_FAULT_DIR
    if year_dir is None and holds_year_run(DEFAULT_YEAR_DIR):
        year_dir = DEFAULT_YEAR_DIR
    return forecast_dir, fault_dir, year_dir
