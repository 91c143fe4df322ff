"""Forecast error metrics.

- `mse_scaled`: mean squared error of the series min-max scaled with the training
  target's range (as paper Table I; dimensionless).
- `mape_pct`: mean absolute percentage error (%) over the samples whose actual power
  exceeds `mape_threshold` x rating (near-zero actuals make MAPE meaningless).
- `mae_kw`, `rmse_kw`: mean absolute and root-mean-square error in kW.
- `skill`: 1 - RMSE_model / RMSE_persistence on the same samples (> 0 beats persistence).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from opfbench.errors import InputError


@dataclass(frozen=True)
class ForecastMetrics:
    """Errors of one model on the test part (units in field names)."""

    mse_scaled: float
    mape_pct: float
    mae_kw: float
    rmse_kw: float
    skill: float
    n_samples: int
    n_mape_samples: int

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def evaluate(
    actual: np.ndarray,
    forecast: np.ndarray,
    persistence: np.ndarray,
    *,
    scale_kw: float,
    rating_kw: float,
    mape_threshold: float,
) -> ForecastMetrics:
    """Metrics of `forecast` against `actual` (kW); `scale_kw` = training target range."""
    a, f, p = (np.asarray(v, dtype=float) for v in (actual, forecast, persistence))
    if not (a.shape == f.shape == p.shape) or a.ndim != 1 or a.size == 0:
        raise InputError("metrics: actual, forecast and persistence must be equal-length non-empty 1-D arrays")
    if not (np.isfinite(a).all() and np.isfinite(f).all() and np.isfinite(p).all()):
        raise InputError("metrics: NaN or infinite values in actual or forecasts")
    if scale_kw <= 0 or rating_kw <= 0 or not 0 <= mape_threshold < 1:
        raise InputError("metrics: scale and rating must be positive, mape_threshold in [0, 1)")
    error = f - a
    rmse = float(np.sqrt(np.mean(error**2)))
    rmse_persistence = float(np.sqrt(np.mean((p - a) ** 2)))
    above = a > mape_threshold * rating_kw
    mape = float(np.mean(np.abs(error[above]) / a[above]) * 100.0) if above.any() else float("nan")
    skill = 1.0 - rmse / rmse_persistence if rmse_persistence > 0 else float("nan")
    return ForecastMetrics(
        mse_scaled=float(np.mean((error / scale_kw) ** 2)),
        mape_pct=mape,
        mae_kw=float(np.mean(np.abs(error))),
        rmse_kw=rmse,
        skill=skill,
        n_samples=int(a.size),
        n_mape_samples=int(above.sum()),
    )
