"""Min-max scaling fitted on training data only (paper §II: inputs normalised to [0, 1])."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.errors import DataError


@dataclass(frozen=True)
class MinMaxScaler:
    """Affine map x -> (x - low) / span, fitted once.

    Fitted on a 1-D array it is one scalar map; fitted on a 2-D array (samples x
    columns) it maps each column, and applies to any array whose last axis is those
    columns. A constant column gets span 1 so it stays finite.
    """

    low: np.ndarray
    span: np.ndarray

    @classmethod
    def fit(cls, values: np.ndarray) -> MinMaxScaler:
        """Fit on `values`: 1-D (one scalar map) or 2-D (one map per column)."""
        data = np.asarray(values, dtype=float)
        if data.ndim not in (1, 2) or data.shape[0] == 0 or not np.isfinite(data).all():
            raise DataError("min-max scaler: training data must be a non-empty, finite 1-D or 2-D array")
        low = data.min(axis=0)
        span = data.max(axis=0) - low
        return cls(low=low, span=np.where(span > 0, span, 1.0))

    def transform(self, values: np.ndarray) -> np.ndarray:
        return (np.asarray(values, dtype=float) - self.low) / self.span

    def inverse(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float) * self.span + self.low
