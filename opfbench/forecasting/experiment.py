"""Run the forecast comparison: chronological split, fit on train, one-step forecasts
over the test part, metrics against the persistence baseline.

Only the training part reaches `fit` (scalers, ARIMA order and parameters, network
weights, best-epoch choice). Test forecasts are rolling one-step-ahead: each uses the
observed power before its time and the weather at its time, without refitting.
Every model's forecast is clipped to the plant's range [0, rating] before it is scored
and stored: a PV or wind plant cannot produce below zero or above its rating, and the
benchmark reads these forecasts as P^F (a no-op for persistence, which repeats
measurements the loaders already check against that range).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from opfbench.errors import InputError
from opfbench.forecasting.arima import Arima
from opfbench.forecasting.base import Forecaster
from opfbench.forecasting.datasets import TARGET, ForecastDataset
from opfbench.forecasting.metrics import ForecastMetrics, evaluate
from opfbench.forecasting.models import MODEL_NAMES, RunSettings, build_model
from opfbench.timing import elapsed_ms, now

REFERENCE = "persistence"


@dataclass(frozen=True)
class ModelRun:
    """One model's outcome: test metrics, wall times (s) and fitted details."""

    metrics: ForecastMetrics
    fit_s: float
    predict_s: float
    details: dict[str, object] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {**self.metrics.as_dict(), "fit_s": self.fit_s, "predict_s": self.predict_s, **self.details}


@dataclass(frozen=True)
class ComparisonResult:
    """Outcome of `run_comparison`.

    Attributes:
        dataset: dataset name.
        rating_kw: plant rating (kW).
        settings: the run settings; seed: the seed used.
        forecasts: test part, column "actual" and one column per model (kW).
        runs: per model, in run order.
        train_range: (first, last) training timestamps.
        weather_lag: steps by which the weather inputs lag the target (0 = at target time).
    """

    dataset: str
    rating_kw: float
    settings: RunSettings
    seed: int
    forecasts: pd.DataFrame
    runs: dict[str, ModelRun]
    train_range: tuple[pd.Timestamp, pd.Timestamp]
    weather_lag: int = 0

    def metrics_table(self) -> dict[str, dict[str, object]]:
        """{model: {mse_scaled, mape_pct, mae_kw, rmse_kw, skill, ..., fit_s, predict_s, details}}"""
        return {name: run.as_dict() for name, run in self.runs.items()}


def run_comparison(
    dataset: ForecastDataset,
    models: tuple[str, ...],
    settings: RunSettings,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> ComparisonResult:
    """Fit every model on the training part and evaluate one-step forecasts on the test part.

    Persistence always runs first: it is the skill reference.
    """
    unknown = [m for m in models if m not in MODEL_NAMES]
    if unknown:
        raise InputError(f"unknown model(s) {', '.join(unknown)}; choose from {', '.join(MODEL_NAMES)}")
    names = [REFERENCE, *(m for m in MODEL_NAMES if m in models and m != REFERENCE)]
    data = dataset.head(settings.rows) if settings.rows is not None and settings.rows < len(dataset.frame) else dataset
    train, test = data.split(settings.train_fraction)
    forecasts = pd.DataFrame({"actual": test[TARGET]})
    timings: dict[str, tuple[float, float, dict[str, object]]] = {}
    for name in names:
        if progress:
            progress(f"{data.name}: fitting {name} on {len(train)} rows")
        model = build_model(name, settings, seed)
        if len(train) <= model.lookback + 1:
            raise InputError(f"{data.name}: {len(train)} training rows are too few for {name} (lookback {model.lookback})")
        start = now()
        model.fit(train)
        fit_s = elapsed_ms(start) / 1e3
        start = now()
        forecast = _test_forecast(model, data.frame, len(train), data.exog_columns)
        forecasts[name] = np.clip(forecast, 0.0, data.rating_kw)
        timings[name] = (fit_s, elapsed_ms(start) / 1e3, _details(model))
    actual = forecasts["actual"].to_numpy()
    scale = float(train[TARGET].max() - train[TARGET].min())
    runs = {
        name: ModelRun(
            evaluate(
                actual,
                forecasts[name].to_numpy(),
                forecasts[REFERENCE].to_numpy(),
                scale_kw=scale if scale > 0 else 1.0,
                rating_kw=data.rating_kw,
                mape_threshold=settings.mape_threshold,
            ),
            *timings[name],
        )
        for name in names
    }
    return ComparisonResult(
        data.name, data.rating_kw, settings, seed, forecasts, runs, (train.index[0], train.index[-1]), data.weather_lag
    )


def _test_forecast(model: Forecaster, frame: pd.DataFrame, n_train: int, exog_columns: list[str]) -> np.ndarray:
    """One-step forecasts for rows n_train.. of `frame`, given `model.warmup` rows before."""
    part = frame.iloc[max(0, n_train - model.warmup) :]
    forecast = model.predict(part[TARGET], part[exog_columns])
    return forecast.reindex(frame.index[n_train:]).to_numpy()


def _details(model: Forecaster) -> dict[str, object]:
    """What was fitted: ARIMA order and convergence; the networks' best epoch(s)."""
    if isinstance(model, Arima):
        return {"arima_order": list(model.order) if model.order is not None else None, "arima_converged": model.converged}
    if hasattr(model, "components"):  # Wavelet-CNN-LSTM: one network per component
        return {"best_epoch": [c.best_epoch for c in model.components]}
    if hasattr(model, "best_epoch"):
        return {"best_epoch": model.best_epoch}
    return {}
