"""Forecasting datasets: the target power series plus the weather inputs of paper §II.

A `ForecastDataset` holds one regular, tz-aware frame with the target column
`TARGET` (power in kW) and the exogenous weather columns. The adapters `pv_dataset`
and `wind_dataset` turn the data contract of `opfbench.data` (`load_pv_minute`,
`load_wind_hourly`) into such a dataset; `forecast_dataset` calls those loaders (imported
lazily, so this module works without `opfbench.data`).

Inputs (paper §II): PV — air temperature (°C), relative humidity (%), global horizontal
irradiance (W/m²); wind — wind speed (m/s), wind direction encoded as sin/cos (the raw
angle jumps at 0/360°), air temperature (°C), relative humidity (%).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.data.cleaning import check_time_index, fill_gaps_linear
from opfbench.errors import DataError, InputError
from opfbench.forecasting.names import FORECAST_DATASETS

TARGET = "power_kw"
"""Name of the target column (power in kW) in every dataset frame."""


PV_COLUMNS = ("pv_ac_kw", "temp_air_c", "relative_humidity_pct", "ghi_wm2")
WIND_COLUMNS = ("wind_power_kw", "wind_speed_ms", "wind_dir_deg", "temp_air_c", "relative_humidity_pct")


@dataclass(frozen=True)
class ForecastDataset:
    """A target power series (kW) with its weather inputs on one regular time grid.

    Attributes:
        name: dataset name ("pv" or "wind").
        frame: tz-aware regular DatetimeIndex; column `TARGET` (kW) and weather columns.
        rating_kw: rated power of the plant (kW), used for the MAPE threshold.
        weather_lag: steps by which the weather columns lag the row time: 0 = weather
            at the target time (a perfect weather forecast, as the paper); 1 = only the
            weather measured one step earlier (a forecast without weather prediction).
    """

    name: str
    frame: pd.DataFrame
    rating_kw: float
    weather_lag: int = 0

    def __post_init__(self) -> None:
        _check_frame(self.frame, self.name)
        if not np.isfinite(self.rating_kw) or self.rating_kw <= 0:
            raise InputError(f"dataset {self.name}: rating_kw must be positive, got {self.rating_kw}")
        if self.weather_lag < 0:
            raise InputError(f"dataset {self.name}: weather_lag must be >= 0, got {self.weather_lag}")

    @property
    def exog_columns(self) -> list[str]:
        """Weather input columns (everything but the target)."""
        return [c for c in self.frame.columns if c != TARGET]

    @property
    def step(self) -> pd.Timedelta:
        """Time step of the grid."""
        return self.frame.index[1] - self.frame.index[0]

    def head(self, rows: int) -> ForecastDataset:
        """The first `rows` rows (for quick runs)."""
        if rows < 2:
            raise InputError(f"dataset {self.name}: need at least 2 rows, got {rows}")
        return ForecastDataset(self.name, self.frame.iloc[:rows], self.rating_kw, self.weather_lag)

    def lag_weather(self, steps: int) -> ForecastDataset:
        """The weather columns shifted `steps` later (row t holds the weather of t - steps);
        the first `steps` rows are dropped."""
        if steps < 0 or steps >= len(self.frame) - 1:
            raise InputError(f"dataset {self.name}: cannot lag the weather by {steps} steps")
        if steps == 0:
            return self
        shifted = self.frame.copy()
        shifted[self.exog_columns] = shifted[self.exog_columns].shift(steps)
        return ForecastDataset(self.name, shifted.iloc[steps:], self.rating_kw, self.weather_lag + steps)

    def split(self, train_fraction: float = 0.9) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Chronological split into (train, test) frames; train = the first fraction."""
        if not 0.0 < train_fraction < 1.0:
            raise InputError(f"train_fraction must be in (0, 1), got {train_fraction}")
        n_train = int(round(len(self.frame) * train_fraction))
        if n_train < 1 or n_train >= len(self.frame):
            raise InputError(f"dataset {self.name}: {len(self.frame)} rows cannot be split at {train_fraction}")
        return self.frame.iloc[:n_train], self.frame.iloc[n_train:]


def pv_dataset(df: pd.DataFrame) -> ForecastDataset:
    """PV dataset from a `load_pv_minute()`-shaped frame (target = `pv_ac_kw`)."""
    source = _require(df, PV_COLUMNS, "pv")
    frame = pd.DataFrame(
        {
            TARGET: source["pv_ac_kw"],
            "temp_air_c": source["temp_air_c"],
            "relative_humidity_pct": source["relative_humidity_pct"],
            "ghi_wm2": source["ghi_wm2"],
        },
        index=df.index,
    )
    return ForecastDataset("pv", _interpolate(frame, "pv"), _rating(df, "pv"))


def wind_dataset(df: pd.DataFrame) -> ForecastDataset:
    """Wind dataset from a `load_wind_hourly()`-shaped frame (target = `wind_power_kw`).

    The direction (degrees) becomes `wind_dir_sin`, `wind_dir_cos` before interpolation,
    so that a gap across north is interpolated along the short way round.
    """
    source = _require(df, WIND_COLUMNS, "wind")
    angle = np.deg2rad(source["wind_dir_deg"].to_numpy(dtype=float))
    frame = pd.DataFrame(
        {
            TARGET: source["wind_power_kw"],
            "wind_speed_ms": source["wind_speed_ms"],
            "wind_dir_sin": np.sin(angle),
            "wind_dir_cos": np.cos(angle),
            "temp_air_c": source["temp_air_c"],
            "relative_humidity_pct": source["relative_humidity_pct"],
        },
        index=df.index,
    )
    return ForecastDataset("wind", _interpolate(frame, "wind"), _rating(df, "wind"))


def forecast_dataset(name: str) -> ForecastDataset:
    """Load a project dataset (BSRN PV at 1 min, TRY wind hourly) through `opfbench.data`."""
    if name not in FORECAST_DATASETS:
        raise InputError(f"unknown dataset {name!r}; choose one of {', '.join(FORECAST_DATASETS)}")
    from opfbench import data

    if name == "pv":
        return pv_dataset(data.load_pv_minute())
    return wind_dataset(data.load_wind_hourly())


def _require(df: pd.DataFrame, columns: tuple[str, ...], name: str) -> pd.DataFrame:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise DataError(f"{name} data: missing column(s) {', '.join(missing)}")
    return df.loc[:, list(columns)].astype(float)


def _rating(df: pd.DataFrame, name: str) -> float:
    if "rating_kw" not in df.attrs:
        raise DataError(f'{name} data: attrs["rating_kw"] (plant rating in kW) is missing')
    return float(df.attrs["rating_kw"])


def _interpolate(frame: pd.DataFrame, name: str) -> pd.DataFrame:
    """Fill gaps linearly in time (edges: nearest value); a column with no data is an error."""
    empty = [c for c in frame.columns if frame[c].notna().sum() == 0]
    if empty:
        raise DataError(f"{name} data: column(s) {', '.join(empty)} contain no values")
    _check_index(frame.index, name)
    return fill_gaps_linear(frame)[0]


def _check_index(index: pd.Index, name: str) -> None:
    """A tz-aware, strictly increasing, evenly spaced index of at least 2 rows."""
    if len(index) < 2:
        raise DataError(f"{name} data: need at least 2 rows, got {len(index)}")
    check_time_index(index, f"{name} data", index[1] - index[0] if isinstance(index, pd.DatetimeIndex) else None)


def _check_frame(frame: pd.DataFrame, name: str) -> None:
    _check_index(frame.index, name)
    if TARGET not in frame.columns:
        raise DataError(f"{name} dataset: target column {TARGET!r} is missing")
    values = frame.to_numpy(dtype=float)
    if not np.isfinite(values).all():
        bad = frame.columns[~np.isfinite(values).all(axis=0)]
        raise DataError(f"{name} dataset: non-finite values left in column(s) {', '.join(bad)}")
