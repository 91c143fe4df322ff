"""One-step-ahead PV and wind power forecasting (paper §II, Table I), leakage-free.

Models share one interface (`Forecaster.fit(train)`, `Forecaster.predict(history, exog)`):
persistence, ARIMA(X), LSTM, CNN-LSTM and Wavelet-CNN-LSTM. `run_comparison` fits them
on the chronological training part and scores rolling one-step forecasts on the test
part; `write_outputs` / `load_forecast` store and read those forecasts
(`DIR/forecast_<dataset>.csv`) for the benchmark's forecast mode.
"""

from opfbench.forecasting.base import Forecaster
from opfbench.forecasting.datasets import TARGET, ForecastDataset, load_dataset, pv_dataset, wind_dataset
from opfbench.forecasting.experiment import ComparisonResult, run_comparison
from opfbench.forecasting.metrics import ForecastMetrics, evaluate
from opfbench.forecasting.models import MODEL_NAMES, RunSettings, build_model, settings_for
from opfbench.forecasting.outputs import forecast_path, load_forecast, write_outputs
from opfbench.forecasting.report import PAPER_TABLE, forecast_page, forecast_section, html_page

__all__ = [
    "MODEL_NAMES",
    "PAPER_TABLE",
    "TARGET",
    "ComparisonResult",
    "ForecastDataset",
    "ForecastMetrics",
    "Forecaster",
    "RunSettings",
    "build_model",
    "evaluate",
    "forecast_page",
    "forecast_path",
    "forecast_section",
    "html_page",
    "load_dataset",
    "load_forecast",
    "pv_dataset",
    "run_comparison",
    "settings_for",
    "wind_dataset",
    "write_outputs",
]
