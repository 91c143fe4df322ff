"""Gap filling and validation shared by all time series.

Gaps (NaN) are filled by linear interpolation in time; gaps at either end of a series,
which have no neighbour on one side, take the nearest valid value. Anything still
non-finite afterwards, a badly ordered time index or a non-positive rating is a
`DataError` that names the file and the column.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from opfbench.errors import DataError


def fill_gaps_linear(df: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, int]]:
    """Fill NaN in every column by time-linear interpolation (nearest value at the ends).

    Returns the filled frame and the number of points filled per column."""
    counts = {col: int(df[col].isna().sum()) for col in df.columns}
    return df.interpolate(method="time", limit_direction="both"), counts


def check_finite(df: pd.DataFrame, name: str) -> None:
    """Raise `DataError` naming ``name`` and the column if any value is NaN or ±inf."""
    for col in df.columns:
        bad = ~np.isfinite(df[col].to_numpy(dtype=float))
        if bad.any():
            raise DataError(
                f"{name}: column {col!r} has {int(bad.sum())} NaN/inf value(s) left after "
                f"cleaning (first at {df.index[bad.argmax()]})"
            )


def check_time_index(index: pd.Index, name: str, step: pd.Timedelta | None = None, column: str = "time") -> None:
    """Require a tz-aware, strictly increasing DatetimeIndex, evenly spaced by ``step``
    when given; otherwise raise `DataError` naming ``name`` and the time column. The one
    time-index check of the project (derived files, forecasting datasets, forecast files)."""
    if not isinstance(index, pd.DatetimeIndex) or index.tz is None:
        raise DataError(f"{name}: column {column!r} is not a time-zone-aware time index")
    if len(index) == 0:
        raise DataError(f"{name}: column {column!r} is empty")
    diffs = np.diff(index.as_unit("ns").asi8)
    if (diffs <= 0).any():
        pos = int((diffs <= 0).argmax()) + 1
        raise DataError(f"{name}: column {column!r} is not strictly increasing at row {pos} ({index[pos]})")
    if step is not None and (diffs != pd.Timedelta(step).as_unit("ns").value).any():
        pos = int((diffs != pd.Timedelta(step).as_unit("ns").value).argmax()) + 1
        raise DataError(f"{name}: column {column!r} is not evenly spaced by {step} at row {pos} ({index[pos]})")


def check_bounds(df: pd.DataFrame, name: str, bounds: dict[str, tuple[float, float]]) -> None:
    """Raise `DataError` naming ``name`` and the column if a value of a column in
    ``bounds`` lies outside its closed interval [low, high]."""
    for col, (low, high) in bounds.items():
        values = df[col].to_numpy(dtype=float)
        bad = (values < low) | (values > high)
        if bad.any():
            raise DataError(
                f"{name}: column {col!r} leaves [{low}, {high}] at {int(bad.sum())} point(s) "
                f"(first {values[bad][0]!r} at {df.index[bad.argmax()]})"
            )


def check_rating(value: float, name: str, what: str) -> float:
    """Return ``value`` as float if it is a finite positive rating, else raise `DataError`."""
    rating = float(value)
    if not math.isfinite(rating) or rating <= 0:
        raise DataError(f"{name}: {what} must be a positive finite rating, got {value!r}")
    return rating
