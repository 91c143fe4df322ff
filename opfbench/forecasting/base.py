"""The one forecaster interface every model implements (scikit-learn shaped).

    model.fit(train)                  # train: frame with `TARGET` (kW) + weather columns
    model.predict(history, exog)      # -> one-step-ahead forecasts (kW)

`history` (power, kW) and `exog` (weather) share one regular time grid. The forecast
for grid time t uses history strictly before t and weather up to and including t
(weather at the target time = a perfect weather forecast, as in paper §II). History at
the last grid time is never used, so it may be NaN: that is how one forecasts the
next, not yet observed, step. Forecasts are returned for the grid times that have
`lookback` observations before them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Self

import numpy as np
import pandas as pd

from opfbench.errors import DataError, InputError
from opfbench.forecasting.datasets import TARGET


class Forecaster(ABC):
    """One-step-ahead forecaster. Subclasses implement `_fit` and `_predict` on arrays.

    Attributes:
        name: model name used in tables and files.
        lookback: number of past observations needed before the first forecast.
        warmup: history length a caller should provide before the first forecast it
            wants for a well-initialised state (>= lookback; larger for ARIMA's filter).
    """

    name: str = "forecaster"

    def __init__(self) -> None:
        self.exog_columns: list[str] | None = None

    @property
    @abstractmethod
    def lookback(self) -> int: ...

    @property
    def warmup(self) -> int:
        return self.lookback

    def fit(self, train: pd.DataFrame) -> Self:
        """Fit on `train` (column `TARGET` in kW plus the weather columns)."""
        if TARGET not in train.columns:
            raise InputError(f"{self.name}: training frame has no {TARGET!r} column")
        exog = train.drop(columns=TARGET)
        y, x = _finite(train[TARGET], "training target"), _finite(exog, "training weather")
        if len(y) <= self.lookback + 1:
            raise InputError(f"{self.name}: {len(y)} training rows, need more than {self.lookback + 1}")
        self.exog_columns = list(exog.columns)
        self._fit(y, x)
        return self

    def predict(self, history: pd.Series, exog: pd.DataFrame) -> pd.Series:
        """One-step-ahead forecasts (kW) for exog.index[lookback:] (see module docstring)."""
        if self.exog_columns is None:
            raise InputError(f"{self.name}: call fit() before predict()")
        if not history.index.equals(exog.index):
            raise InputError(f"{self.name}: history and exog must share the same time index")
        if list(exog.columns) != self.exog_columns:
            raise InputError(f"{self.name}: exog columns {list(exog.columns)} differ from training {self.exog_columns}")
        if len(history) <= self.lookback:
            raise InputError(f"{self.name}: {len(history)} history rows, need more than lookback {self.lookback}")
        y = history.to_numpy(dtype=float).copy()
        _finite(y[:-1], "history")
        x = _finite(exog, "weather")
        forecast = self._predict(y, x)
        return pd.Series(forecast, index=exog.index[self.lookback :], name=self.name)

    @abstractmethod
    def _fit(self, y: np.ndarray, x: np.ndarray) -> None:
        """Fit on power y (n,) in kW and weather x (n, k)."""

    @abstractmethod
    def _predict(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Forecasts for positions lookback..n-1; position i may use y[:i] and x[:i+1]."""


def _finite(values: pd.Series | pd.DataFrame | np.ndarray, what: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if not np.isfinite(array).all():
        raise DataError(f"{what} contains NaN or infinite values")
    return array
