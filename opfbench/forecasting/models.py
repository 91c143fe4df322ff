"""Model registry and the run settings per dataset (full and `--quick`).

Full-run budgets (how long they take: README, "Command line"):
- PV (1-min, 43 200 rows): 30-min input window, 20 epochs of 16 384 windows drawn
  from the ~35 000 training windows; ARIMA fitted on the last 5 000 training minutes.
- Wind (hourly, 8 760 rows): 24-h window, 40 epochs over all ~7 100 training
  windows; ARIMA fitted on the last 5 000 training hours.
Quick runs use the first few days (PV) / weeks (wind), 2 epochs of 512 windows, a
3-order ARIMA grid: a smoke test of the whole pipeline, not a result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from opfbench.errors import InputError
from opfbench.forecasting.arima import Arima, Order, order_grid
from opfbench.forecasting.base import Forecaster
from opfbench.forecasting.names import MODEL_NAMES
from opfbench.forecasting.persistence import Persistence

if TYPE_CHECKING:  # torch is imported only when a network model is built
    from opfbench.forecasting.neural import TrainConfig


@dataclass(frozen=True)
class RunSettings:
    """Settings of one comparison run.

    Attributes:
        rows: use only the first `rows` rows of the dataset (None = all).
        window: input window length (steps).
        epochs, windows_per_epoch, batch_size, learning_rate: network training (see TrainConfig).
        arima_orders, arima_fit_samples: ARIMA order grid and fitting sample count.
        train_fraction: chronological share of rows used for training.
        mape_threshold: MAPE counts samples whose actual exceeds this share of the rating.
        wavelet, wavelet_level: DWT of the Wavelet-CNN-LSTM.
        threads: torch CPU threads. Results are reproducible for a fixed count. Default 1:
            with 2 threads training slows down by an order of magnitude whenever another
            process keeps the other core busy (thread oversubscription).
    """

    rows: int | None
    window: int
    epochs: int
    windows_per_epoch: int | None
    arima_orders: tuple[Order, ...]
    arima_fit_samples: int
    batch_size: int = 256
    learning_rate: float = 1e-3
    train_fraction: float = 0.9
    mape_threshold: float = 0.1
    wavelet: str = "db2"
    wavelet_level: int = 3
    threads: int = 1

    def train_config(self, seed: int) -> "TrainConfig":
        from opfbench.forecasting.neural import TrainConfig

        return TrainConfig(
            window=self.window,
            epochs=self.epochs,
            windows_per_epoch=self.windows_per_epoch,
            batch_size=self.batch_size,
            learning_rate=self.learning_rate,
            seed=seed,
            threads=self.threads,
        )


_QUICK_ORDERS: tuple[Order, ...] = ((1, 0, 0), (1, 1, 0), (2, 0, 1))

SETTINGS: dict[tuple[str, bool], RunSettings] = {
    ("pv", False): RunSettings(
        rows=None, window=30, epochs=20, windows_per_epoch=16384, arima_orders=order_grid(), arima_fit_samples=5000
    ),
    ("pv", True): RunSettings(
        rows=4 * 1440, window=24, epochs=2, windows_per_epoch=512, arima_orders=_QUICK_ORDERS, arima_fit_samples=1000
    ),
    ("wind", False): RunSettings(
        rows=None, window=24, epochs=40, windows_per_epoch=None, arima_orders=order_grid(), arima_fit_samples=5000
    ),
    ("wind", True): RunSettings(
        rows=42 * 24, window=24, epochs=2, windows_per_epoch=512, arima_orders=_QUICK_ORDERS, arima_fit_samples=500
    ),
}


def settings_for(dataset: str, quick: bool) -> RunSettings:
    """Settings of `dataset` ("pv" or "wind") for a full or quick run."""
    try:
        return SETTINGS[(dataset, quick)]
    except KeyError:
        raise InputError(f"no forecast settings for dataset {dataset!r}") from None


def build_model(name: str, settings: RunSettings, seed: int) -> Forecaster:
    """A fresh, unfitted model by name (one of MODEL_NAMES)."""
    if name == "persistence":
        return Persistence()
    if name == "arima":
        return Arima(orders=settings.arima_orders, fit_samples=settings.arima_fit_samples)
    if name not in MODEL_NAMES:
        raise InputError(f"unknown model {name!r}; choose from {', '.join(MODEL_NAMES)}")
    from opfbench.forecasting.networks import NetConfig  # torch only for the network models
    from opfbench.forecasting.neural import NeuralForecaster, WaveletForecaster

    train = settings.train_config(seed)
    if name == "lstm":
        return NeuralForecaster(name, NetConfig(conv=False), train)
    if name == "cnn-lstm":
        return NeuralForecaster(name, NetConfig(conv=True), train)
    return WaveletForecaster(name, NetConfig(conv=True), train, settings.wavelet, settings.wavelet_level)
