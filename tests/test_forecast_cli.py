"""`opfbench forecast --quick` end to end on synthetic data: determinism, files, report,
and no leakage through the run itself (scalers, order search, training see only the
training part). The runs use `TINY`: the `--quick` settings with one epoch of 64 windows
and one ARIMA order on 300 samples, so that the whole pipeline runs in seconds (what is tested is the
contract, not the forecast quality)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import opfbench.cli as cli
from opfbench.forecasting.datasets import wind_dataset
from opfbench.forecasting.experiment import run_comparison
from opfbench.forecasting.models import MODEL_NAMES
from opfbench.forecasting.outputs import load_forecast
from tests.support.forecast_synthetic import synthetic_wind_hourly, tiny_settings, use_tiny_synthetic

TIMINGS = ("fit_s", "predict_s")


@pytest.fixture
def run_cli(monkeypatch, capsys):
    """Run `opfbench forecast ...` on synthetic data; returns (exit code, stdout, stderr)."""
    use_tiny_synthetic(monkeypatch)

    def run(*argv: str) -> tuple[int, str, str]:
        code = cli.main(["forecast", *argv])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


def _without_timings(table: dict) -> dict:
    return {model: {k: v for k, v in row.items() if k not in TIMINGS} for model, row in table.items()}


def test_quick_run_is_deterministic_and_writes_its_files(run_cli, tmp_path):
    code, first, _ = run_cli("--dataset", "pv", "--quick", "--json", "--out", str(tmp_path))
    assert code == 0
    code, second, _ = run_cli("--dataset", "pv", "--quick", "--json")
    assert code == 0
    one, two = json.loads(first), json.loads(second)
    assert list(one) == list(MODEL_NAMES)
    assert _without_timings(one) == _without_timings(two)
    for row in one.values():
        assert {"mse_scaled", "mape_pct", "mae_kw", "rmse_kw", "skill", "fit_s"} <= set(row)
        assert np.isfinite(row["rmse_kw"]) and row["n_samples"] == 576
    assert one["persistence"]["skill"] == 0.0

    actual = load_forecast(tmp_path, "pv", "actual")
    assert str(actual.index.tz) == "UTC" and len(actual) == 576
    for model in MODEL_NAMES:
        series = load_forecast(tmp_path, "pv", model)
        assert series.index.equals(actual.index)
        rmse = float(np.sqrt(np.mean((series - actual) ** 2)))
        assert rmse == pytest.approx(one[model]["rmse_kw"], rel=1e-9)

    saved = json.loads((tmp_path / "forecast_pv.json").read_text())
    assert saved["run"]["n_test"] == 576 and saved["run"]["settings"]["window"] == 24
    html = (tmp_path / "forecast_pv.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "data:image/png;base64," in html
    assert "http://" not in html and "https://" not in html and "<script" not in html
    assert "0.0092" in html and "7.09" in html  # paper Table I, Wavelet-CNN-LSTM PV
    assert f"{one['lstm']['mse_scaled']:.5f}" in html


def test_quick_wind_table_and_model_subset(run_cli):
    code, out, err = run_cli("--dataset", "wind", "--quick", "--models", "arima", "--weather", "previous")
    assert code == 0
    lines = out.splitlines()
    assert "weather lag 1 step(s)" in lines[0]
    assert lines[1].split()[:3] == ["model", "mse_scaled", "mape_pct"]
    assert [line.split()[0] for line in lines[2:]] == ["persistence", "arima"]
    assert "0.0589" in lines[3] and "17.60" in lines[3]  # paper Table I, ARIMA wind
    assert "fitting arima" in err


def test_bad_arguments_exit_2(run_cli):
    code, _, err = run_cli("--dataset", "pv", "--quick", "--models", "lstm,prophet")
    assert code == 2 and "unknown model" in err
    code, _, _ = run_cli("--dataset", "hydro")
    assert code == 2


def test_load_forecast_errors(tmp_path):
    from opfbench.errors import DataError, InputError

    with pytest.raises(DataError, match="no forecast file"):
        load_forecast(tmp_path, "pv", "lstm")
    pd.DataFrame({"actual": [1.0]}, index=pd.Index(["2016-06-01T00:00:00+0000"], name="timestamp")).to_csv(
        tmp_path / "forecast_pv.csv"
    )
    with pytest.raises(InputError, match="available: actual"):
        load_forecast(tmp_path, "pv", "lstm")


def test_run_does_not_leak_the_test_part():
    """Changing the last test hours changes nothing before them, in any model."""
    settings = tiny_settings("wind")
    raw = synthetic_wind_hourly(days=42)
    base = run_comparison(wind_dataset(raw), MODEL_NAMES, settings, seed=0)
    cut = raw.index[-30]
    changed_raw = raw.copy()
    later = changed_raw.index >= cut
    changed_raw.loc[later, "wind_power_kw"] = 11.0
    changed_raw.loc[later, "wind_speed_ms"] = 30.0
    changed = run_comparison(wind_dataset(changed_raw), MODEL_NAMES, settings, seed=0)
    earlier = base.forecasts.index < cut
    pd.testing.assert_frame_equal(base.forecasts[earlier], changed.forecasts[earlier])
    assert not base.forecasts[~earlier].equals(changed.forecasts[~earlier])
