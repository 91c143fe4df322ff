"""Studies on a SimBench grid's own profiles: the period at its 15-min steps, per-element
scenarios in the tasks (loaded by spec in the worker), night modes on its solar units, the
oracle forecast, and what such a case refuses before any work."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from opfbench.errors import InputError
from opfbench.io import load_case
from opfbench.scenario import Scenario
from opfbench.study import StudyConfig
from opfbench.study.run_family import prepare, run_study
from opfbench.study.task_scenarios import chunk_scenario

SPEC = "simbench:1-LV-rural1--0-sw"
DAWN = "2016-06-21T03:00..2016-06-21T07:00"  # night until 05:00, PV rising after


@pytest.fixture(scope="module")
def dawn_run(tmp_path_factory):
    config = StudyConfig(
        cases=(SPEC,),
        strategies=("no-action", "llma", "lfma", "acopf", "socp"),
        ks=(0.0,),
        period=DAWN,
        chunk="day",
    )
    return run_study(config, tmp_path_factory.mktemp("dawn"))


def test_period_runs_at_the_profiles_step(dawn_run):
    table = pd.read_parquet(dawn_run.out / "steps.parquet")
    assert dawn_run.period.step_h == 0.25 and len(dawn_run.period.index) == 16
    assert table.groupby(["strategy", "night_mode", "forecast"]).size().eq(16).all() and (table.case == SPEC).all()
    assert (table.status == "ok").all()
    manifest = json.loads((dawn_run.out / "manifest.json").read_text())
    info = manifest["cases"][SPEC]
    assert info["loads"] == 13 and "SimBench 1-LV-rural1--0-sw profiles" in info["series"]
    assert any("taps applied" in n for n in info["notes"])
    assert any("SimBench 1-LV-rural1--0-sw profiles" in s for s in manifest["data_sources"])


def test_the_tasks_use_the_case_series(dawn_run):
    s = dawn_run.summary.set_index(["strategy", "night_mode", "forecast"])
    case = load_case(SPEC)
    times = dawn_run.period.index
    expected = Scenario.of_case(case, times)
    na = run_strategy_energy(expected, "no-action") * 0.25
    assert s.loc[("no-action", "connected", "off")].energy_kwh == pytest.approx(na, rel=1e-12)
    opf = s.loc[("acopf", "connected", "off")].energy_kwh
    assert opf <= s.loc[("lfma", "connected", "off")].energy_kwh + 1e-9 and opf < na


def run_strategy_energy(scenario, name: str) -> float:
    from opfbench.registry.catalog import run_strategy

    return float(np.nansum(run_strategy(name, scenario, 0.0).losses_kw))


def test_night_modes_and_oracle_on_the_solar_units():
    period = prepare(StudyConfig(cases=(SPEC,), period=DAWN, strategies=("llma",))).period
    profiles, night = period.profiles, period.night
    case = load_case(SPEC)
    own = Scenario.of_case(case, period.index)
    off = chunk_scenario(SPEC, "disconnected", "oracle", profiles, night, 15, pd.Timedelta("15min"), "")
    solar = case.network.der_solar
    assert solar.all() and (off.der_p_mw[night[:15]] == 0).all()
    assert np.array_equal(off.der_p_mw[~night[:15]], own.der_p_mw[:15][~night[:15]])
    assert np.array_equal(off.der_p_forecast_mw[-1], own.der_p_mw[15])  # the chunk's next step
    assert np.array_equal(off.load_p_mw, own.load_p_mw[:15])
    q = chunk_scenario(SPEC, "connected-q", "off", profiles, night, 16, pd.Timedelta("15min"), "")
    assert np.array_equal(q.pv_night_q, night) and q.der_p_forecast_mw is None


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"forecast": ("off", "wavelet-cnn-lstm")}, "forecasts are of the BSRN Payerne PV plant"),
        ({"cases": ("paper33", SPEC)}, "give --step-minutes"),
        ({"period": "2017-01-01T00:00..2017-01-02T00:00"}, "leaves the data"),
    ],
)
def test_refused_before_any_work(fields, message):
    config = StudyConfig(**({"cases": (SPEC,), "strategies": ("llma",)} | fields))
    with pytest.raises(InputError, match=message):
        prepare(config)


def test_mixed_cases_at_a_common_step():
    family = prepare(StudyConfig(cases=("paper33", SPEC), strategies=("llma",), step_minutes=15))
    period, tasks = family.period, family.tasks
    assert len(period.index) == 96 and {t.case for t in tasks} == {"paper33", SPEC}


def test_a_case_without_der_gets_a_note_in_the_run_and_the_report(tmp_path, capsys):
    from opfbench.io import NO_DER_NOTE
    from opfbench.report import write_report

    config = StudyConfig(
        cases=("case33bw",), strategies=("no-action", "llma"), ks=(0.0,), period="2016-03-01T10:00..2016-03-01T11:00"
    )
    run = run_study(config, tmp_path / "run")
    assert f"note: case33bw: {NO_DER_NOTE}" in run.notes and capsys.readouterr().err == ""  # the library prints nothing
    manifest = json.loads((run.out / "manifest.json").read_text())
    assert manifest["cases"]["case33bw"]["notes"] == [NO_DER_NOTE]
    page = write_report(run.out).read_text()
    assert "case33bw: the case has no DER: every strategy gives the no-action result" in page
