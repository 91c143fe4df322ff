"""Persistence baseline: the forecast for t is the power observed at t - 1 step."""

from __future__ import annotations

import numpy as np

from opfbench.forecasting.base import Forecaster


class Persistence(Forecaster):
    """ŷ(t) = y(t - 1). Ignores the weather; nothing to fit."""

    name = "persistence"

    @property
    def lookback(self) -> int:
        return 1

    def _fit(self, y: np.ndarray, x: np.ndarray) -> None:
        """Nothing to learn."""

    def _predict(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        return y[:-1].copy()
