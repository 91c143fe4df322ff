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


def holds_run(folder: Path) -> bool:
    """A run folder: `opfbench run` writes its manifest before any task (a damaged one is
    the report inputs' to name)."""
    return (folder / "manifest.json").exists()


def holds_forecasts(folder: Path) -> bool:
    return any((folder / f"forecast_{d}.json").is_file() for d in ("pv", "wind"))


def holds_fault_study(folder: Path) -> bool:
    return (folder / "fault.parquet").is_file()


def holds_year_run(folder: Path) -> bool:
    """A finished `opfbench run --period year` folder: its manifest and summary."""
    try:
        manifest = json.loads((folder / "manifest.json").read_bytes().decode("utf-8"))
    except (OSError, ValueError):  # UnicodeDecodeError is a ValueError
        return False
    config = manifest.get("config") if isinstance(manifest, dict) else None
    return isinstance(config, dict) and config.get("period") == "year" and (folder / "summary.csv").is_file()


def check_given(forecast_dir: Path | None, fault_dir: Path | None, year_dir: Path | None) -> None:
    """A folder given on the command line must hold what it is given for: a forecast
    run's metrics, a fault study's table, a finished year run (manifest.json with period
    'year' and summary.csv)."""
    if forecast_dir is not None and not holds_forecasts(forecast_dir):
        raise InputError(
            f"--forecast-dir {forecast_dir} holds no forecast run (forecast_pv.json or forecast_wind.json); write one "
            f"with `opfbench forecast --dataset pv --out {forecast_dir}`"
        )
    if fault_dir is not None and not holds_fault_study(fault_dir):
        raise InputError(
            f"--fault-dir {fault_dir} holds no fault study (fault.parquet); write one with "
            f"`opfbench fault CASE --out {fault_dir}`"
        )
    if year_dir is not None and not holds_year_run(year_dir):
        raise InputError(
            f"--year-dir {year_dir} holds no finished year run (manifest.json with period 'year' and "
            f"summary.csv); write one with `opfbench run --period year --out {year_dir}`"
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
