"""Inputs are read as given or refused with one message naming them (exit code 2) — never
read silently as something else: periods in ISO 8601 only, local times the daylight-saving
change skips or repeats, the step on every period, empty paths, a forecast file's own
rating, a file path given where a forecast model's name belongs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.errors import DataError, InputError
from opfbench.forecasting.outputs import load_forecast
from opfbench.study.config import StudyConfig
from opfbench.study.periods import resolve_period

GRID = ["--strategies", "no-action", "--k", "0", "--night-modes", "connected", "--forecast", "off", "--workers", "1"]


def _cli(capsys, argv: list[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


@pytest.fixture
def no_run(monkeypatch):
    """`opfbench run` must refuse before any task runs."""

    def fail(*args, **kwargs):
        raise AssertionError("a task ran before the input was refused")

    monkeypatch.setattr("opfbench.study.tasks.run_task", fail)


@pytest.mark.parametrize(
    ("period", "message"),
    [
        ("01/06/2016..02/06/2016", "period: cannot read time '01/06/2016': give an ISO 8601 date or date-time"),
        ("2016-06-01..28/06/2016", "period: cannot read time '28/06/2016'"),
        ("June 1..June 2", "period: cannot read time 'June 1'"),
        ("now..tomorrow", "period: cannot read time 'now'"),
        (
            "2016-03-27T02:30..2016-03-27T04:00",
            "period: 2016-03-27T02:30 does not exist in Europe/Zurich: the clocks skip that hour",
        ),
        (
            "2016-10-30T01:00..2016-10-30T02:30",
            "period: 2016-10-30T02:30 occurs twice in Europe/Zurich (the clocks go back when summer time ends); add the "
            "offset: 2016-10-30T02:30:00+02:00 (the first) or 2016-10-30T02:30:00+01:00 (the second)",
        ),
        ("2017-01-01..2017-01-02", "period '2017-01-01..2017-01-02' leaves the data: they cover 2016-01-01T00:00:00+01:00"),
        ("0001-01-01..2016-06-29", "period: 0001-01-01 lies outside the data, which cover 2016-01-01T00:00:00+01:00"),
        ("2016-06-28T24:00..2016-06-29", "period: cannot read time '2016-06-28T24:00'"),
        ("2016-02-30..2016-03-01", "period: cannot read time '2016-02-30'"),
        ("2016-06-28..", "period: cannot read time ''"),
        (
            "2016-06-28T10:00..2016-06-28T10:00:30",
            "period '2016-06-28T10:00..2016-06-28T10:00:30' lasts 0.5 min, less than one step of 1 min (--step-minutes)",
        ),
        ("2016-06-28T12:00..2016-06-28T10:00", "END must come after START"),
    ],
)
def test_period_times_iso_8601_only_and_never_in_a_clock_change(capsys, tmp_path, no_run, period, message):
    code, err = _cli(capsys, ["run", "--period", period, *GRID, "--out", str(tmp_path / "run")])
    assert code == 2 and err.startswith("opfbench run: error: ") and message in err, err
    assert err.count("\n") == 1 and not (tmp_path / "run" / "manifest.json").exists()


def test_iso_8601_forms_and_offsets_are_read_as_written():
    window = resolve_period("2016-06-28T10:00+02:00..2016-06-28T11:00Z", "sun")  # 10:00 to 13:00 local
    assert (window.index[0].hour, window.index[-1].hour, len(window.index)) == (10, 12, 180)
    assert resolve_period("2016-10-30T02:30+01:00..2016-10-30T03:30", "sun").index[0].utcoffset().seconds == 3600
    assert len(resolve_period("20160628..20160629", "sun").index) == 1440  # ISO's basic format


@pytest.mark.parametrize(
    ("period", "step", "message"),
    [
        ("paper-day", "1e9", "period 'paper-day' lasts 1440 min, less than one step of 1e+09 min (--step-minutes)"),
        ("2016-06-28..2016-06-29", "1e9", "period '2016-06-28..2016-06-29' lasts 1440 min, less than one step of 1e+09"),
        ("year", "1e300", "period 'year' lasts 527040 min, less than one step of 1e+300 min"),
        ("paper-day", "0.5", "--step-minutes 0.5: the finest data (BSRN PV) are 1-minute values; the step must be ≥ 1 min"),
        ("paper-day", "1e-300", "the step must be ≥ 1 min"),
        ("2016-12-31T23:00..2017-01-01", "1", "its last step 2016-12-31T23:59:00+01:00 lies after the data's last"),
    ],
)
def test_step_outside_the_data_or_the_period_exit_2(capsys, tmp_path, no_run, period, step, message):
    argv = ["run", "--period", period, "--step-minutes", step, *GRID, "--out", str(tmp_path / "run")]
    code, err = _cli(capsys, argv)
    assert code == 2 and message in err and "Traceback" not in err and err.count("\n") == 1, err


def test_step_minutes_is_honoured_on_the_paper_day():
    day = resolve_period("paper-day", "20:00-05:00", 5.0)
    assert len(day.index) == 288 and day.step_h == pytest.approx(5 / 60)
    minute = resolve_period("paper-day", "20:00-05:00")
    np.testing.assert_array_equal(day.profiles.pv.to_numpy(), minute.profiles.pv.to_numpy()[::5])


def test_a_single_quarter_hour_counts_a_quarter_hour():
    one = resolve_period("2016-01-01T00:00..2016-01-01T00:15", "sun")
    assert len(one.index) == 1 and one.step_h == 0.25  # was 1/60: the energy of one step 15 times too small


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--out", ""],
        ["run", "--out", "  "],
        ["run", "--fault-dir", ""],
        ["run", "--forecast-dir", ""],
        ["report", ""],
        ["report", "reports/run", "--out", ""],
        ["fault", "paper33", "--out", ""],
        ["forecast", "--dataset", "pv", "--out", ""],
        ["run", "--out", "a\x00b"],
    ],
)
def test_an_empty_path_is_not_the_current_folder(capsys, tmp_path, monkeypatch, no_run, argv):
    monkeypatch.chdir(tmp_path)
    code, err = _cli(capsys, argv)
    assert code == 2 and ("an empty path" in err or "contains a NUL byte" in err), err
    assert list(tmp_path.iterdir()) == []  # nothing written where the user stands


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["pf", "paper33", "--load-scale", "1_0"], "argument --load-scale: not a number: '1_0'"),  # float() reads 10
        (["pf", "paper33", "--load-scale", "١"], "argument --load-scale: not a number: '١'"),  # float() reads 1
        (["snapshot", "paper33", "--strategy", "llma", "--k", "Infinity"], "argument --k: must be finite, got Infinity"),
        (["run", "--price", "nan"], "argument --price: must be finite, got nan"),
        (["run", "--price", "1e999"], "argument --price: must be finite, got 1e999"),
        (["run", "--currency", " "], "currency must be a printable, non-empty label (e.g. EUR), got ' '"),
        (["fault", "paper33", "--fault-bus", "17", "--variants", "emf-pu=3"], "needs an EMF within [0.5, 1.5] p.u., got 3.0"),
    ],
)
def test_numbers_and_labels_written_oddly_exit_2(capsys, tmp_path, no_run, argv, message):
    code, err = _cli(capsys, [*argv, "--out", str(tmp_path / "out")] if argv[0] in ("run", "fault") else argv)
    assert code == 2 and message in err.splitlines()[-1] and "Traceback" not in err, err  # argparse adds its usage


def test_a_forecast_folder_that_is_a_file(tmp_path):
    target = tmp_path / "forecast"
    target.write_text("")
    with pytest.raises(DataError, match=f"forecast folder {target} is not a folder"):
        load_forecast(target, "pv", "lstm")


def test_a_file_path_as_forecast_is_an_unknown_model_name(capsys, tmp_path, no_run):
    csv = tmp_path / "my_forecast.csv"
    csv.write_text("timestamp,lstm\n")
    code, err = _cli(capsys, ["run", "--forecast", str(csv), "--strategies", "llma", "--out", str(tmp_path / "run")])
    assert code == 2 and f"unknown forecast source '{csv}'; choose off, oracle or a forecasting model's name" in err
    assert "persistence, arima, lstm, cnn-lstm, wavelet-cnn-lstm" in err and "reports/forecast" in err
    with pytest.raises(InputError, match="unknown forecast source 'Oracle'"):
        StudyConfig(forecast=("Oracle",))


def _forecast_folder(tmp_path, values, rating_kw):
    stamps = pd.date_range("2016-06-01T10:00", periods=len(values), freq="1min", tz="UTC")
    frame = pd.DataFrame({"timestamp": stamps.strftime("%Y-%m-%dT%H:%M:%S%z"), "actual": values, "lstm": values})
    frame.to_csv(tmp_path / "forecast_pv.csv", index=False)
    (tmp_path / "forecast_pv.json").write_text(json.dumps({"run": {"rating_kw": rating_kw}, "metrics": {}}))
    return tmp_path


@pytest.mark.parametrize(
    ("rating", "message"),
    [
        (1e9, "run.rating_kw is 1000000000.0, but the pv plant the benchmark uses is rated 10 kW"),
        (5, "run.rating_kw is 5, but the pv plant the benchmark uses is rated 10 kW"),
        ("10", "run.rating_kw is '10', but"),
        (None, "run.rating_kw is None, but"),
    ],
)
def test_a_forecast_files_own_rating_cannot_widen_the_range(tmp_path, rating, message):
    folder = _forecast_folder(tmp_path, [1.0, 2e4, 3.0], rating)  # 20 MW from a 10 kW plant
    with pytest.raises(DataError, match=message):
        load_forecast(folder, "pv", "lstm")


def test_a_forecast_beyond_the_plant_is_refused_not_clipped(tmp_path):
    folder = _forecast_folder(tmp_path, [1.0, 20.0, 3.0], 10.0)
    with pytest.raises(DataError, match=r"line 3: '20.0' is outside the plant's range \[0, 10\] kW"):
        load_forecast(folder, "pv", "lstm")
    assert load_forecast(_forecast_folder(tmp_path, [1.0, 10.0, 3.0], 10.0), "pv", "lstm").max() == 10.0


def test_a_forecast_missing_a_later_chunks_daylight_is_refused_before_any_task(capsys, tmp_path, no_run):
    from opfbench.data import load_pv_minute

    pv = load_pv_minute()["pv_ac_kw"].loc["2016-06-28 03:00":"2016-06-28 12:00"]  # UTC: covers the first two chunks only
    frame = pv.to_frame("actual").assign(lstm=pv)
    frame.index = frame.index.strftime("%Y-%m-%dT%H:%M:%S%z").rename("timestamp")
    frame.to_csv(tmp_path / "forecast_pv.csv")
    argv = ["run", "--strategies", "llma", "--k", "0", "--night-modes", "connected", "--forecast", "lstm"]
    code, err = _cli(capsys, [*argv, "--forecast-dir", str(tmp_path), "--workers", "1", "--out", str(tmp_path / "run")])
    assert code == 2 and err.count("\n") == 1, err
    assert f"forecast 'lstm' in {tmp_path} has no value for" in err and "first 2016-06-28 12:01:00+00:00" in err, err
