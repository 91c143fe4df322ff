"""Windowed neural forecasters: LSTM, CNN-LSTM and Wavelet-CNN-LSTM (paper §II).

Sample for target time t (window w): a sequence of w steps s = t-w+1 .. t whose step s
holds the signal value at s-1 and the weather at s. The signal is the past power
window y(t-w) .. y(t-1), optionally transformed window by window (a wavelet
component); the weather runs up to the target time t. The label is the same transform
applied to the window ending at t, taken at t — so a wavelet component label uses data
up to t only, and the components of the labels add up to y(t).

Scaling (min-max, fitted on the training part only): weather per column; signal and
label with one map fitted on the training labels. Training: Adam, MSE loss,
mini-batches; each epoch draws a random subset of the training windows; the
chronologically last `val_fraction` of the windows is held out and the epoch with the
lowest validation MSE is kept. Seeds are fixed and torch runs deterministically on CPU.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import torch
from numpy.lib.stride_tricks import sliding_window_view

from opfbench.errors import InputError
from opfbench.forecasting.base import Forecaster
from opfbench.forecasting.networks import NetConfig, SequenceRegressor
from opfbench.forecasting.scaling import MinMaxScaler
from opfbench.forecasting.wavelet import WaveletComponent, check_level, component_names

WindowTransform = Callable[[np.ndarray], np.ndarray]
"""Maps windows (N, w) to transformed windows (N, w), row by row."""

PREDICT_CHUNK = 8192


@dataclass(frozen=True)
class TrainConfig:
    """Training settings.

    Attributes:
        window: number of past steps in each input window.
        epochs: training epochs.
        windows_per_epoch: training windows drawn (without replacement) per epoch;
            None = all.
        batch_size: mini-batch size.
        learning_rate: Adam step size.
        val_fraction: chronologically last share of training windows held out to pick
            the best epoch (0 = keep the last epoch).
        seed: seed of torch and numpy generators.
        threads: torch CPU threads.
    """

    window: int = 30
    epochs: int = 10
    windows_per_epoch: int | None = None
    batch_size: int = 256
    learning_rate: float = 1e-3
    val_fraction: float = 0.1
    seed: int = 0
    threads: int = 1

    def __post_init__(self) -> None:
        if self.window < 2 or self.epochs < 1 or self.batch_size < 1 or not 0 <= self.val_fraction < 1:
            raise InputError(f"invalid training settings: {self}")


@dataclass(frozen=True)
class EpochLog:
    """Mean training loss and validation MSE (scaled units) of one epoch."""

    epoch: int
    train_loss: float
    val_mse: float


class NeuralForecaster(Forecaster):
    """LSTM (`net.conv=False`) or CNN-LSTM (`net.conv=True`) on an optionally transformed window."""

    def __init__(self, name: str, net: NetConfig, train: TrainConfig, transform: WindowTransform | None = None) -> None:
        super().__init__()
        self.name = name
        self.net = net
        self.train_config = train
        self.transform = transform
        self.log: list[EpochLog] = []
        self.best_epoch: int | None = None

    @property
    def lookback(self) -> int:
        return self.train_config.window

    def _fit(self, y: np.ndarray, x: np.ndarray) -> None:
        _torch_setup(self.train_config)
        self._x_scaler = MinMaxScaler.fit(x)
        w = self.train_config.window
        labels = self._apply(sliding_window_view(y, w)[1:])[:, -1]
        self._s_scaler = MinMaxScaler.fit(labels)
        sequences = self._sequences(y, x)
        self._model = SequenceRegressor(sequences.shape[-1], w, self.net)
        self._train(sequences, torch.from_numpy(self._s_scaler.transform(labels).astype(np.float32)))

    def _predict(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        _torch_setup(self.train_config)
        scaled = _evaluate(self._model, self._sequences(y, x))
        return self._s_scaler.inverse(scaled.astype(float))

    def _apply(self, windows: np.ndarray) -> np.ndarray:
        return np.asarray(windows, dtype=float) if self.transform is None else self.transform(windows)

    def _sequences(self, y: np.ndarray, x: np.ndarray) -> torch.Tensor:
        """Input sequences (n - w, w, 1 + k) for targets w .. n-1 (y[n-1] unused)."""
        w = self.train_config.window
        signal = self._s_scaler.transform(self._apply(sliding_window_view(y[:-1], w)))
        weather = sliding_window_view(self._x_scaler.transform(x)[1:], w, axis=0).transpose(0, 2, 1)
        sequences = np.concatenate([signal[:, :, None], weather], axis=2)
        return torch.from_numpy(sequences.astype(np.float32))

    def _train(self, sequences: torch.Tensor, labels: torch.Tensor) -> None:
        cfg = self.train_config
        rng = np.random.default_rng(cfg.seed)
        n_val = int(round(len(labels) * cfg.val_fraction))
        n_fit = len(labels) - n_val
        if n_fit < 1:
            raise InputError(f"{self.name}: no training windows left after the validation hold-out")
        optimizer = torch.optim.Adam(self._model.parameters(), lr=cfg.learning_rate)
        loss_fn = torch.nn.MSELoss()
        best_state: dict[str, torch.Tensor] | None = None
        best_score = float("inf")
        self.log = []
        for epoch in range(cfg.epochs):
            self._model.train()
            chosen = rng.permutation(n_fit)[: cfg.windows_per_epoch]
            losses = []
            for start in range(0, len(chosen), cfg.batch_size):
                batch = torch.from_numpy(chosen[start : start + cfg.batch_size])
                optimizer.zero_grad()
                loss = loss_fn(self._model(sequences[batch]), labels[batch])
                loss.backward()
                optimizer.step()
                losses.append(loss.item())
            train_loss = float(np.mean(losses))
            val_mse = (
                float(np.mean((_evaluate(self._model, sequences[n_fit:]) - labels[n_fit:].numpy()) ** 2))
                if n_val
                else float("nan")
            )
            self.log.append(EpochLog(epoch + 1, train_loss, val_mse))
            score = val_mse if n_val else -epoch
            if score < best_score:
                best_score, self.best_epoch = score, epoch + 1
                best_state = {k: v.detach().clone() for k, v in self._model.state_dict().items()}
        if best_state is None:
            raise InputError(f"{self.name}: training gave no finite validation loss in {cfg.epochs} epoch(s)")
        self._model.load_state_dict(best_state)


class WaveletForecaster(Forecaster):
    """Wavelet-CNN-LSTM: one network per DWT component of the window, forecasts summed.

    Each component network gets its own component of the input window (plus the
    weather) and learns the same component at the target time; the sum of the
    component forecasts is the power forecast.
    """

    def __init__(self, name: str, net: NetConfig, train: TrainConfig, wavelet: str = "db2", level: int = 3) -> None:
        super().__init__()
        check_level(train.window, wavelet, level)
        self.name = name
        self.components = [
            NeuralForecaster(f"{name}[{label}]", net, replace(train, seed=train.seed + j), WaveletComponent(j, wavelet, level))
            for j, label in enumerate(component_names(level))
        ]

    @property
    def lookback(self) -> int:
        return self.components[0].lookback

    def _fit(self, y: np.ndarray, x: np.ndarray) -> None:
        for component in self.components:
            component._fit(y, x)

    def _predict(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.sum([component._predict(y, x) for component in self.components], axis=0)


def _evaluate(model: SequenceRegressor, sequences: torch.Tensor) -> np.ndarray:
    model.eval()
    with torch.no_grad():
        parts = [model(sequences[i : i + PREDICT_CHUNK]) for i in range(0, len(sequences), PREDICT_CHUNK)]
    return torch.cat(parts).numpy() if parts else np.empty(0, dtype=np.float32)


def _torch_setup(config: TrainConfig) -> None:
    torch.set_num_threads(config.threads)
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(config.seed)
