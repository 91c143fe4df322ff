"""The benchmark runner on the paper day (local rules only, to stay fast)."""

import numpy as np
import pytest

from opfbench.study import BenchmarkConfig, day_scenarios, run_benchmark, summarize
from opfbench.errors import DataError, InputError


@pytest.fixture(scope="module")
def table():
    config = BenchmarkConfig(strategies=("no-action", "llma", "lfma"), ks=(0.0, 0.8), night="20:00-05:00")
    return run_benchmark(config, progress=lambda msg: None)


def test_table_is_tidy_and_complete(table):
    assert len(table) == 3 * 2 * 2 * 2 * 1440  # strategies × k × night modes × forecast × steps
    assert (table.status == "ok").all()
    assert table.groupby(["strategy", "k", "night_mode", "forecast"]).size().eq(1440).all()


def test_summary_orders_rules_and_reserve(table):
    s = summarize(table).set_index(["strategy", "k", "night_mode", "forecast"])
    for k in (0.0, 0.8):
        row = lambda name: s.loc[(name, k, "connected", "off")]  # noqa: E731
        assert row("lfma").energy_kwh < row("llma").energy_kwh < row("no-action").energy_kwh
        assert row("no-action").savings_pct == pytest.approx(0.0)
    assert s.loc[("lfma", 0.0, "connected", "off")].energy_kwh < s.loc[("lfma", 0.8, "connected", "off")].energy_kwh
    # energy = average kW × 24 h for a whole day of 1-min steps
    row = s.loc[("no-action", 0.0, "connected", "off")]
    assert row.energy_kwh == pytest.approx(row.avg_loss_kw * 24.0)


def test_disconnecting_pv_in_the_clock_window_removes_evening_output():
    index, scenarios = day_scenarios(BenchmarkConfig(night="20:00-05:00", forecast=("off",)))
    on, off = scenarios["connected", "off"], scenarios["disconnected", "off"]
    evening = (index.hour >= 20)
    pv = np.array([kind == "PV" for kind in on.net.der_kinds])
    assert on.der_p_mw[evening][:, pv].sum() > 0 and off.der_p_mw[evening][:, pv].sum() == 0
    np.testing.assert_array_equal(on.der_p_mw[:, ~pv], off.der_p_mw[:, ~pv])


@pytest.mark.parametrize("kwargs, message", [
    ({"strategies": ("magic",)}, "unknown strategy"),
    ({"night_modes": ("sometimes",)}, "unknown night mode"),
    ({"ks": ()}, "nothing to run"),
])
def test_bad_configuration(kwargs, message):
    with pytest.raises(InputError, match=message):
        BenchmarkConfig(**kwargs)


def test_missing_model_forecast_is_a_clear_error(tmp_path):
    with pytest.raises(DataError, match="no forecast file"):
        day_scenarios(BenchmarkConfig(forecast=("wavelet-cnn-lstm",), forecast_dir=str(tmp_path)))


def test_bad_night_window():
    with pytest.raises(InputError, match="night"):
        day_scenarios(BenchmarkConfig(night="dusk"))


def test_model_forecast_feeds_algorithm_3_one_step_ahead(tmp_path):
    """A forecast file indexed by target time: P^F at step t is the forecast for t + 1."""
    from opfbench.data import load_pv_minute, paper_day

    pv = load_pv_minute()["pv_ac_kw"]
    window = pv.loc["2016-06-28 00:00":"2016-06-28 23:00"]  # the test split starts at UTC midnight
    frame = window.to_frame("actual").assign(mymodel=0.5 * window)
    frame.index = frame.index.strftime("%Y-%m-%dT%H:%M:%S%z").rename("timestamp")
    frame.to_csv(tmp_path / "forecast_pv.csv")
    config = BenchmarkConfig(forecast=("mymodel",), night_modes=("connected",), forecast_dir=str(tmp_path))
    index, scenarios = day_scenarios(config)
    sc = scenarios["connected", "mymodel"]
    pv_units = np.array([kind == "PV" for kind in sc.net.der_kinds])
    ahead = pv.reindex((index + (index[1] - index[0])).tz_convert("UTC")).to_numpy() / 10.0
    covered = (index + (index[1] - index[0])).tz_convert("UTC") >= window.index[0]
    expected = np.where(covered, 0.5 * ahead, paper_day()["pv"].to_numpy())  # uncovered night: P^F = P^C (= 0)
    assert (~covered).sum() == 119 and np.all(expected[~covered] == 0)
    np.testing.assert_allclose(sc.der_p_forecast_mw[:, pv_units], expected[:, None] * sc.net.der_rating_mw[pv_units])
    np.testing.assert_array_equal(sc.der_p_forecast_mw[:, ~pv_units], sc.der_p_mw[:, ~pv_units])  # DFIG: P^F = P^C
    np.testing.assert_allclose(sc.der_p_mw[:, pv_units][:, 0], paper_day()["pv"].to_numpy() * 0.6)


def test_model_forecast_not_covering_the_day_is_refused(tmp_path):
    from opfbench.data import load_pv_minute

    pv = load_pv_minute()["pv_ac_kw"].loc["2016-06-28 03:00":"2016-06-28 12:00"]
    frame = pv.to_frame("actual").assign(mymodel=pv)
    frame.index = frame.index.strftime("%Y-%m-%dT%H:%M:%S%z").rename("timestamp")
    frame.to_csv(tmp_path / "forecast_pv.csv")
    with pytest.raises(DataError, match="daylight step"):
        day_scenarios(BenchmarkConfig(forecast=("mymodel",), forecast_dir=str(tmp_path)))


def _check_day(table):
    """Per step: the SOCP bound is below every strategy's losses and the AC OPF beats every
    local rule; per configuration: LFMA < LLMA < no action."""
    wide = table.pivot_table(index=["time", "k", "night_mode"], columns="strategy", values="losses_kw")
    bound = table[table.strategy == "acopf"].set_index(["time", "k", "night_mode"])["lower_bound_kw"]
    bound = bound.reindex(wide.index)
    for name in wide.columns:
        assert (bound <= wide[name] + 1e-3).all(), name
        if name not in ("acopf", "socp"):
            assert (wide["acopf"] <= wide[name] + 1e-3).all(), name
    energy = table.groupby(["strategy", "k", "night_mode"]).losses_kw.sum()
    for k in table.k.unique():
        for mode in table.night_mode.unique():
            e = energy.xs((k, mode), level=("k", "night_mode"))
            assert e["acopf"] <= e["lfma"] < e["llma"] < e["no-action"]


def test_whole_day_every_strategy_at_k0():
    table = run_benchmark(BenchmarkConfig(ks=(0.0,), night_modes=("connected",), forecast=("off",)),
                          progress=lambda msg: None)
    assert (table.status == "ok").all() and (table.voltage_violation < 1e-6).all()
    _check_day(table)


@pytest.mark.slow
def test_whole_default_grid():
    """The main job's full grid (`opfbench run` defaults): every step solved, orderings hold."""
    table = run_benchmark(BenchmarkConfig(), progress=lambda msg: None)
    assert (table.status == "ok").all()
    _check_day(table[table.forecast == "off"])
