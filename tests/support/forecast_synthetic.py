"""Synthetic frames with the columns of the opfbench.data contract, for forecasting tests.

PV: a clear-sky-like bell (UTC day), cut by a slowly varying cloud factor (AR(1)), through
a linear PV model with a temperature coefficient. Wind: AR(1) wind speed, random-walk
direction, a cubic power curve between cut-in and rated speed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from opfbench.forecasting.models import settings_for  # the real one: `use_tiny_synthetic` replaces it


def _ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    shocks = rng.normal(0.0, sigma, n)
    out = np.empty(n)
    out[0] = shocks[0]
    for i in range(1, n):
        out[i] = phi * out[i - 1] + shocks[i]
    return out


def synthetic_pv_minute(days: int = 6, seed: int = 0, rating_kw: float = 10.0) -> pd.DataFrame:
    """`load_pv_minute()`-shaped frame: 1-min, tz-aware UTC, from 2016-06-01."""
    rng = np.random.default_rng(seed)
    index = pd.date_range("2016-06-01", periods=days * 1440, freq="1min", tz="UTC")
    hour = index.hour.to_numpy() + index.minute.to_numpy() / 60.0
    clear = 950.0 * np.clip(np.sin(np.pi * (hour - 4.0) / 16.0), 0.0, None) ** 1.2
    cloud = np.clip(1.0 - np.abs(_ar1(rng, len(index), 0.98, 0.05)), 0.15, 1.0)
    ghi = clear * cloud
    temp = 14.0 + 9.0 * np.clip(np.sin(np.pi * (hour - 6.0) / 16.0), 0.0, None) + _ar1(rng, len(index), 0.99, 0.05)
    pv = np.clip(rating_kw * ghi / 1000.0 * (1.0 - 0.004 * (temp - 25.0)), 0.0, rating_kw)
    frame = pd.DataFrame(
        {
            "ghi_wm2": ghi,
            "dni_wm2": 0.7 * ghi,
            "dhi_wm2": 0.3 * ghi,
            "temp_air_c": temp,
            "relative_humidity_pct": np.clip(95.0 - 2.5 * temp, 5.0, 100.0),
            "pressure_hpa": 960.0 + _ar1(rng, len(index), 0.999, 0.01),
            "pv_ac_kw": pv,
        },
        index=index,
    )
    frame.attrs["rating_kw"] = rating_kw
    return frame


def synthetic_wind_hourly(days: int = 60, seed: int = 0, rating_kw: float = 11.0) -> pd.DataFrame:
    """`load_wind_hourly()`-shaped frame: hourly, tz-aware UTC, from 2016-01-01."""
    rng = np.random.default_rng(seed)
    index = pd.date_range("2016-01-01", periods=days * 24, freq="1h", tz="UTC")
    speed = np.clip(7.0 + _ar1(rng, len(index), 0.95, 1.0), 0.0, None)
    direction = np.mod(220.0 + np.cumsum(rng.normal(0.0, 8.0, len(index))), 360.0)
    cut_in, rated, cut_out = 3.0, 12.0, 25.0
    curve = np.clip((speed**3 - cut_in**3) / (rated**3 - cut_in**3), 0.0, 1.0)
    power = np.where(speed < cut_out, rating_kw * curve, 0.0)
    hour = index.hour.to_numpy()
    temp = 5.0 + 4.0 * np.sin(2 * np.pi * (hour - 9) / 24) + _ar1(rng, len(index), 0.98, 0.3)
    frame = pd.DataFrame(
        {
            "wind_speed_ms": speed,
            "wind_dir_deg": direction,
            "temp_air_c": temp,
            "relative_humidity_pct": np.clip(80.0 - 1.5 * temp + _ar1(rng, len(index), 0.9, 2.0), 5.0, 100.0),
            "pressure_hpa": 1010.0 + _ar1(rng, len(index), 0.99, 0.5),
            "wind_power_kw": power,
        },
        index=index,
    )
    frame.attrs["rating_kw"] = rating_kw
    return frame


def tiny_settings(dataset: str, quick: bool = True):
    """The quick settings, cut to one epoch of 64 windows and one ARIMA order fitted on 300 samples."""
    return replace(settings_for(dataset, quick), epochs=1, windows_per_epoch=64, arima_orders=((1, 0, 0),), arima_fit_samples=300)


def use_tiny_synthetic(monkeypatch) -> None:
    """`opfbench forecast` on synthetic data (6 days of PV, 60 of wind) with `tiny_settings`:
    the whole pipeline in seconds."""
    from opfbench.forecasting import models
    from opfbench.forecasting.datasets import pv_dataset, wind_dataset

    synthetic = {
        "pv": lambda: pv_dataset(synthetic_pv_minute(days=6)),
        "wind": lambda: wind_dataset(synthetic_wind_hourly(days=60)),
    }
    monkeypatch.setattr("opfbench.forecasting.datasets.forecast_dataset", lambda name: synthetic[name]())
    monkeypatch.setattr(models, "settings_for", tiny_settings)
