"""Every forecaster: the fit/predict contract and NO LOOK-AHEAD.

Leakage test: the forecast for time t must not change when the power at t and later or
the weather after t are replaced by anything else. Each test also checks that the
forecast for t DOES react to the power at t-1 (and, for models with weather inputs, to
the weather at t), so the equality cannot hold trivially.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from opfbench.errors import DataError, InputError
from opfbench.forecasting.datasets import TARGET, pv_dataset, wind_dataset
from opfbench.forecasting.models import MODEL_NAMES, build_model, settings_for
from opfbench.forecasting.networks import NetConfig
from opfbench.forecasting.neural import NeuralForecaster, TrainConfig
from opfbench.forecasting.persistence import Persistence
from tests.support.forecast_synthetic import synthetic_pv_minute, synthetic_wind_hourly

TINY = replace(
    settings_for("pv", quick=True), epochs=1, windows_per_epoch=256, arima_orders=((1, 0, 0), (1, 1, 1)), arima_fit_samples=600
)


@pytest.fixture(scope="module")
def pv():
    ds = pv_dataset(synthetic_pv_minute(days=2, seed=5))
    return ds.frame.iloc[:1800], ds.frame  # train, all


@pytest.fixture(scope="module")
def fitted(pv):
    train, _ = pv
    return {name: build_model(name, TINY, seed=0).fit(train) for name in MODEL_NAMES}


def _split(frame: pd.DataFrame) -> tuple[pd.Series, pd.DataFrame]:
    return frame[TARGET].copy(), frame.drop(columns=TARGET).copy()


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_no_look_ahead(name, pv, fitted):
    _, frame = pv
    model = fitted[name]
    part = frame.iloc[1500:2300]  # spans the end of training and the unseen rest
    history, exog = _split(part)
    t = part.index[600]  # a daytime minute (UTC ~15:00), power > 0
    assert history[t] > 0.5
    base = model.predict(history, exog)
    assert base.index[0] == part.index[model.lookback] and base.index[-1] == part.index[-1]

    rng = np.random.default_rng(9)
    future_y, future_x = history.copy(), exog.copy()
    future_y[future_y.index >= t] = rng.uniform(0, 30, (future_y.index >= t).sum())
    after = exog.index > t
    future_x.loc[after] = rng.uniform(-500, 1500, (after.sum(), exog.shape[1]))
    changed = model.predict(future_y, future_x)
    np.testing.assert_array_equal(base[:t].to_numpy(), changed[:t].to_numpy())
    assert not np.array_equal(base[base.index > t].to_numpy(), changed[changed.index > t].to_numpy())

    previous = history.copy()
    previous[previous.index[previous.index.get_loc(t) - 1]] += 2.0
    assert model.predict(previous, exog)[t] != base[t], "forecast ignores the last observation"
    if name != "persistence":
        weather = exog.copy()
        weather.loc[t] = weather.loc[t] * 1.5 + 1.0
        assert model.predict(history, weather)[t] != base[t], "forecast ignores the weather at the target time"


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_next_step_forecast_with_unknown_last_value(name, pv, fitted):
    _, frame = pv
    history, exog = _split(frame.iloc[1700:1900])
    full = fitted[name].predict(history, exog)
    history.iloc[-1] = np.nan  # the step being forecast is not observed yet
    unknown = fitted[name].predict(history, exog)
    assert np.isfinite(unknown.iloc[-1])
    np.testing.assert_array_equal(full.to_numpy(), unknown.to_numpy())


def test_persistence_is_the_previous_value(pv):
    train, frame = pv
    history, exog = _split(frame.iloc[:100])
    forecast = Persistence().fit(train).predict(history, exog)
    np.testing.assert_array_equal(forecast.to_numpy(), history.to_numpy()[:-1])
    assert forecast.index.equals(history.index[1:])


def test_arima_order_search(fitted):
    arima = fitted["arima"]
    assert [f.order for f in arima.search] == [(1, 0, 0), (1, 1, 1)]
    chosen = next(f for f in arima.search if f.order == arima.order)
    valid = [f for f in arima.search if np.isfinite(f.aic) and f.converged == chosen.converged]
    assert chosen.aic == min(f.aic for f in valid)


def test_wavelet_model_has_one_network_per_component(fitted):
    model = fitted["wavelet-cnn-lstm"]
    assert [c.name for c in model.components] == [f"wavelet-cnn-lstm[{c}]" for c in ("A3", "D3", "D2", "D1")]
    assert all(c.net.conv for c in model.components)


def test_paper_architecture():
    model = build_model("cnn-lstm", TINY, seed=0)
    assert (model.net.hidden, model.net.layers, model.net.dropout) == (150, 3, 0.5)
    assert (model.net.filters, model.net.kernel, model.net.pool) == (16, 4, 2)
    assert build_model("lstm", TINY, seed=0).net.conv is False


def test_training_reduces_the_loss():
    ds = wind_dataset(synthetic_wind_hourly(days=40, seed=2))
    model = NeuralForecaster("lstm", NetConfig(conv=False), TrainConfig(window=24, epochs=4, windows_per_epoch=512))
    model.fit(ds.frame)
    assert len(model.log) == 4
    assert model.log[-1].train_loss < 0.7 * model.log[0].train_loss
    assert model.best_epoch == 1 + int(np.argmin([e.val_mse for e in model.log]))


def test_contract_errors(pv, fitted):
    train, frame = pv
    history, exog = _split(frame.iloc[:200])
    with pytest.raises(InputError, match="fit"):
        Persistence().predict(history, exog)
    with pytest.raises(InputError, match="columns"):
        fitted["lstm"].predict(history, exog[exog.columns[::-1]])
    with pytest.raises(InputError, match="same time index"):
        fitted["lstm"].predict(history.iloc[1:], exog)
    holey = history.copy()
    holey.iloc[50] = np.nan
    with pytest.raises(DataError, match="NaN"):
        fitted["lstm"].predict(holey, exog)
    with pytest.raises(InputError, match="unknown model"):
        build_model("prophet", TINY, seed=0)
