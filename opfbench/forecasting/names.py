"""The forecasting datasets and models by name (no heavy imports: the CLI reads these to
build its parser)."""

FORECAST_DATASETS = ("pv", "wind")
"""Dataset names: BSRN PV at 1 min, TRY wind hourly."""

MODEL_NAMES = ("persistence", "arima", "lstm", "cnn-lstm", "wavelet-cnn-lstm")
"""Model names, in table order."""
