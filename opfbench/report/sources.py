"""Which forecast and fault folders the report reads (light: pathlib only).

`opfbench run` and `opfbench report` use the same rule, so a rebuild gives the same page:
a folder given on the command line is used; otherwise `reports/forecast` and
`reports/fault` are used when they hold a forecast run's metrics or a fault study's table.
Without a forecast folder the report reads the committed docs/forecast metrics."""

from __future__ import annotations

from pathlib import Path

DEFAULT_FORECAST_DIR = Path("reports/forecast")
DEFAULT_FAULT_DIR = Path("reports/fault")


def holds_forecasts(folder: Path) -> bool:
    return any((folder / f"forecast_{d}.json").is_file() for d in ("pv", "wind"))


def holds_fault_study(folder: Path) -> bool:
    return (folder / "fault.parquet").is_file()


def report_sources(forecast_dir: Path | None, fault_dir: Path | None) -> tuple[Path | None, Path | None]:
    """(forecast folder, fault folder) the report reads: as given, else the defaults when they hold data."""
    if forecast_dir is None and holds_forecasts(DEFAULT_FORECAST_DIR):
        forecast_dir = DEFAULT_FORECAST_DIR
    if fault_dir is None and holds_fault_study(DEFAULT_FAULT_DIR):
        fault_dir = DEFAULT_FAULT_DIR
    return forecast_dir, fault_dir
