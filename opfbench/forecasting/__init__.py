"""One-step-ahead PV and wind power forecasting (paper §II, Table I), leakage-free.

Models share one interface (`Forecaster.fit(train)`, `Forecaster.predict(history, exog)`):
persistence, ARIMA(X), LSTM, CNN-LSTM and Wavelet-CNN-LSTM. `run_comparison` fits them
on the chronological training part and scores rolling one-step forecasts on the test
part; `write_outputs` / `load_forecast` store and read those forecasts
(`DIR/forecast_<dataset>.csv`) for the benchmark's forecast mode.

Names are imported on first use (PEP 562), so `import opfbench.forecasting` does not
load torch, statsmodels or matplotlib; each is imported only when a model or a plot
needs it.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "Forecaster": "base",
    "TARGET": "datasets",
    "ForecastDataset": "datasets",
    "forecast_dataset": "datasets",
    "pv_dataset": "datasets",
    "wind_dataset": "datasets",
    "ComparisonResult": "experiment",
    "run_comparison": "experiment",
    "ForecastMetrics": "metrics",
    "evaluate": "metrics",
    "MODEL_NAMES": "models",
    "RunSettings": "models",
    "build_model": "models",
    "settings_for": "models",
    "forecast_path": "outputs",
    "load_forecast": "outputs",
    "write_outputs": "outputs",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value
