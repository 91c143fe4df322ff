"""Files of a forecast run, and reading them back for the benchmark's forecast mode.

- `DIR/forecast_<dataset>.csv`: test-part one-step forecasts, index `timestamp`
  (ISO 8601, UTC), column `actual` and one column per model, all in kW.
- `DIR/forecast_<dataset>.json`: run metadata and the metrics table.
- `DIR/forecast_<dataset>.html`: self-contained report page (see `report`).
"""

from __future__ import annotations

import io
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd

from opfbench.data.cleaning import check_time_index
from opfbench.errors import DataError, InputError
from opfbench.folders import check_out_dir
from opfbench.forecasting.experiment import ComparisonResult
from opfbench.jsonio import write_atomic, write_json

_TIME_FORMAT = "%Y-%m-%dT%H:%M:%S%z"


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
    """Write the forecasts (CSV) and the run's metadata and metrics (JSON) of `result` into
    `directory` (created), each atomically."""
    out = check_out_dir(directory)
    csv = write_atomic(
        forecast_path(out, result.dataset, "csv"), result.forecasts.to_csv(index_label="timestamp", date_format=_TIME_FORMAT)
    )
    meta = write_json(
        forecast_path(out, result.dataset, "json"), {"run": run_metadata(result), "metrics": result.metrics_table()}
    )
    return [csv, meta]


def load_forecast(directory: str | Path, dataset: str, model: str) -> pd.Series:
    """Test-part one-step forecasts (kW) of `model` written by `write_outputs`.

    `model` may also be "actual". The index is tz-aware (UTC). The values must be
    finite and within [0, rating] of the embedded dataset's plant — the plant the
    benchmark scales them by; the run's JSON beside the CSV, when present, must record
    that rating (a forecast of another plant is refused, not rescaled). A timestamp that
    is not ISO 8601 with an offset, a non-numeric or out-of-range value, a file that is
    not UTF-8 is a `DataError` naming file, column and line — never clipped, never skipped.
    """
    path = forecast_path(directory, dataset, "csv")
    if Path(directory).exists() and not Path(directory).is_dir():
        raise DataError(f"forecast folder {directory} is not a folder; give the --out folder of `opfbench forecast`")
    if not path.is_file():
        raise DataError(f"no forecast file {path}; run `opfbench forecast --dataset {dataset} --out {directory}`")
    rating = _rating_kw(forecast_path(directory, dataset, "json"), dataset)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text file (byte {exc.start})") from None
    try:
        frame = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: unreadable CSV ({exc})") from None
    if "timestamp" not in frame.columns:
        raise DataError(f"{path}: no 'timestamp' column")
    if model not in frame.columns or model == "timestamp":
        columns = [c for c in frame.columns if c != "timestamp"]
        raise InputError(f"{path} has no model {model!r}; available: {', '.join(columns)}")
    index = pd.to_datetime(frame["timestamp"], format=_TIME_FORMAT, utc=True, errors="coerce")
    _first_bad(path, "timestamp", frame["timestamp"], index.isna().to_numpy(), "is not a timestamp like 2016-06-01T00:00:00+0000")
    check_time_index(pd.DatetimeIndex(index), str(path), column="timestamp")
    values = pd.to_numeric(frame[model], errors="coerce").to_numpy(dtype=float)
    _first_bad(path, model, frame[model], np.isnan(values), "is not a number")
    _first_bad(path, model, frame[model], ~np.isfinite(values), "is not finite")
    _first_bad(path, model, frame[model], (values < 0) | (values > rating), f"is outside the plant's range [0, {rating:g}] kW")
    return pd.Series(values, index=pd.DatetimeIndex(index, name="timestamp"), name=model)


def _rating_kw(meta: Path, dataset: str) -> float:
    """The rating (kW) of the embedded dataset's plant, after checking that the forecast
    run's JSON `meta` (when present) records the same."""
    from opfbench.forecasting.datasets import forecast_dataset

    rating = forecast_dataset(dataset).rating_kw
    if not meta.exists():
        return rating
    try:
        recorded = json.loads(meta.read_text(encoding="utf-8"))["run"]["rating_kw"]
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise DataError(f"{meta}: no readable run.rating_kw ({type(exc).__name__}: {exc})") from None
    if isinstance(recorded, bool) or not isinstance(recorded, (int, float)) or float(recorded) != rating:
        raise DataError(
            f"{meta}: run.rating_kw is {recorded!r}, but the {dataset} plant the benchmark uses is rated {rating:g} kW; "
            f"these forecasts are of another plant — rerun `opfbench forecast --dataset {dataset} --out {meta.parent}`"
        )
    return rating


def _first_bad(path: Path, column: str, raw: pd.Series, bad: np.ndarray, problem: str) -> None:
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(f"{path}, column {column!r}, line {i + 2}: {raw.iloc[i]!r} {problem} ({int(bad.sum())} such row(s))")
