"""Dataset adapters, chronological split, min-max scaling and metrics."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.errors import DataError, InputError
from opfbench.forecasting.datasets import TARGET, ForecastDataset, forecast_dataset, pv_dataset, wind_dataset
from opfbench.forecasting.metrics import evaluate
from opfbench.forecasting.scaling import MinMaxScaler
from tests.support.forecast_synthetic import synthetic_pv_minute, synthetic_wind_hourly


def test_pv_adapter_selects_the_paper_inputs():
    ds = pv_dataset(synthetic_pv_minute(days=2))
    assert list(ds.frame.columns) == [TARGET, "temp_air_c", "relative_humidity_pct", "ghi_wm2"]
    assert ds.rating_kw == 10.0 and ds.step == pd.Timedelta("1min")
    assert str(ds.frame.index.tz) == "UTC"


def test_wind_adapter_encodes_direction_as_sin_cos():
    raw = synthetic_wind_hourly(days=3)
    ds = wind_dataset(raw)
    assert ds.exog_columns == ["wind_speed_ms", "wind_dir_sin", "wind_dir_cos", "temp_air_c", "relative_humidity_pct"]
    angle = np.deg2rad(raw["wind_dir_deg"].to_numpy())
    np.testing.assert_allclose(ds.frame["wind_dir_sin"], np.sin(angle))
    np.testing.assert_allclose(ds.frame["wind_dir_cos"], np.cos(angle))


def test_gaps_are_filled_linearly_in_time():
    raw = synthetic_pv_minute(days=1)
    expected = raw["pv_ac_kw"].copy()
    raw.iloc[600:603, raw.columns.get_loc("pv_ac_kw")] = np.nan
    filled = pv_dataset(raw).frame[TARGET]
    line = np.linspace(expected.iloc[599], expected.iloc[603], 5)[1:-1]
    np.testing.assert_allclose(filled.iloc[600:603], line)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda df: df.drop(columns="ghi_wm2"), "missing column"),
        (lambda df: df.tz_localize(None), "time-zone-aware"),
        (lambda df: df.drop(df.index[5]), "not evenly spaced"),
        (lambda df: df.assign(temp_air_c=np.nan), "no values"),
    ],
)
def test_bad_input_frames_are_rejected(mutate, message):
    raw = synthetic_pv_minute(days=1)
    bad = mutate(raw)
    bad.attrs["rating_kw"] = 10.0
    with pytest.raises(DataError, match=message):
        pv_dataset(bad)


def test_missing_rating_is_an_error():
    raw = synthetic_pv_minute(days=1)
    raw.attrs.clear()
    with pytest.raises(DataError, match="rating_kw"):
        pv_dataset(raw)


def test_split_is_chronological_90_10():
    ds = pv_dataset(synthetic_pv_minute(days=1))
    train, test = ds.split(0.9)
    assert len(train) == 1296 and len(test) == 144
    assert train.index[-1] < test.index[0]
    assert train.index.append(test.index).equals(ds.frame.index)
    with pytest.raises(InputError):
        ds.split(1.0)


def test_load_dataset_reads_the_embedded_data_and_rejects_unknown_names():
    pv = forecast_dataset("pv")
    assert pv.rating_kw == 10.0 and len(pv.frame) == 43_200
    with pytest.raises(InputError, match="unknown dataset"):
        forecast_dataset("hydro")


def test_dataset_rejects_nan_and_bad_rating():
    frame = pv_dataset(synthetic_pv_minute(days=1)).frame.copy()
    with pytest.raises(InputError):
        ForecastDataset("pv", frame, 0.0)
    frame.iloc[3, 0] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        ForecastDataset("pv", frame, 10.0)


def test_minmax_scaler_uses_only_the_fitted_data():
    train = np.array([[0.0, 5.0], [10.0, 5.0], [5.0, 5.0]])
    scaler = MinMaxScaler.fit(train)
    np.testing.assert_allclose(scaler.transform(train)[:, 0], [0.0, 1.0, 0.5])
    np.testing.assert_allclose(scaler.transform([[20.0, 6.0]]), [[2.0, 1.0]])  # constant column: span 1
    np.testing.assert_allclose(scaler.inverse(scaler.transform(train)), train)
    scalar = MinMaxScaler.fit(np.array([2.0, 4.0]))
    np.testing.assert_allclose(scalar.transform(np.ones((2, 3)) * 3.0), 0.5)


def test_metrics_by_hand():
    actual = np.array([0.0, 2.0, 4.0, 10.0])
    forecast = np.array([1.0, 2.0, 5.0, 8.0])
    persistence = np.array([0.0, 0.0, 2.0, 4.0])
    m = evaluate(actual, forecast, persistence, scale_kw=10.0, rating_kw=10.0, mape_threshold=0.1)
    assert m.mae_kw == pytest.approx(1.0)
    assert m.rmse_kw == pytest.approx(np.sqrt(6.0 / 4))
    assert m.mse_scaled == pytest.approx(6.0 / 4 / 100)
    assert m.mape_pct == pytest.approx(100 * (0 + 0.25 + 0.2) / 3)  # the 0 kW sample is below 1 kW
    assert m.n_mape_samples == 3
    assert m.skill == pytest.approx(1 - np.sqrt(1.5) / np.sqrt((0 + 4 + 4 + 36) / 4))
    with pytest.raises(InputError):
        evaluate(actual, forecast[:3], persistence, scale_kw=1.0, rating_kw=1.0, mape_threshold=0.1)


def test_lag_weather_shifts_only_the_inputs():
    ds = pv_dataset(synthetic_pv_minute(days=1))
    lagged = ds.lag_weather(1)
    assert lagged.weather_lag == 1 and len(lagged.frame) == len(ds.frame) - 1
    np.testing.assert_array_equal(lagged.frame[TARGET].to_numpy(), ds.frame[TARGET].to_numpy()[1:])
    np.testing.assert_array_equal(lagged.frame["ghi_wm2"].to_numpy(), ds.frame["ghi_wm2"].to_numpy()[:-1])
    assert ds.lag_weather(0) is ds
    with pytest.raises(InputError):
        ds.lag_weather(-1)
