"""Files of a forecast run, and reading them back for the benchmark's forecast mode.

- `DIR/forecast_<dataset>.csv`: test-part one-step forecasts, index `timestamp`
  (ISO 8601, UTC), column `actual` and one column per model, all in kW.
- `DIR/forecast_<dataset>.json`: run metadata and the metrics table.
- `DIR/forecast_<dataset>.html`: self-contained report page (see `report`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import pandas as pd

from opfbench.errors import DataError, InputError
from opfbench.forecasting.experiment import ComparisonResult
from opfbench.forecasting.report import forecast_page


def forecast_path(directory: str | Path, dataset: str, suffix: str = "csv") -> Path:
    return Path(directory) / f"forecast_{dataset}.{suffix}"


def run_metadata(result: ComparisonResult) -> dict[str, object]:
    """Everything needed to know how the numbers were made (JSON-ready)."""
    return {
        "dataset": result.dataset,
        "rating_kw": result.rating_kw,
        "seed": result.seed,
        "weather_lag_steps": result.weather_lag,
        "settings": asdict(result.settings),
        "train": [str(t) for t in result.train_range],
        "test": [str(result.forecasts.index[0]), str(result.forecasts.index[-1])],
        "n_test": len(result.forecasts),
    }


def write_outputs(result: ComparisonResult, directory: str | Path) -> list[Path]:
    """Write the CSV, JSON and HTML files of `result` into `directory` (created)."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    csv = forecast_path(out, result.dataset, "csv")
    result.forecasts.to_csv(csv, index_label="timestamp", date_format="%Y-%m-%dT%H:%M:%S%z")
    meta = forecast_path(out, result.dataset, "json")
    payload = {"run": run_metadata(result), "metrics": result.metrics_table()}
    meta.write_text(json.dumps(json_safe(payload), indent=2) + "\n")
    html = forecast_path(out, result.dataset, "html")
    html.write_text(forecast_page(result))
    return [csv, meta, html]


def load_forecast(directory: str | Path, dataset: str, model: str) -> pd.Series:
    """Test-part one-step forecasts (kW) of `model` written by `write_outputs`.

    `model` may also be "actual". The index is tz-aware (UTC).
    """
    path = forecast_path(directory, dataset, "csv")
    if not path.is_file():
        raise DataError(f"no forecast file {path}; run `opfbench forecast --dataset {dataset} --out {directory}`")
    frame = pd.read_csv(path, index_col="timestamp")
    if model not in frame.columns:
        raise InputError(f"{path} has no model {model!r}; available: {', '.join(frame.columns)}")
    series = frame[model].astype(float)
    series.index = pd.to_datetime(series.index, utc=True)
    series.index.name = "timestamp"
    return series


def json_safe(value: object) -> object:
    """NaN/inf become null (strict JSON)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value
