"""The study runner: grid checks, periods, scenarios per night mode and forecast, the run
folder (resume, refusal, lock) and the tables (local rules only, to stay fast, except one
whole day under every strategy)."""

import json
import os

import numpy as np
import pandas as pd
import pytest

from opfbench.capability import PAPER_KS
from opfbench.cli import main
from opfbench.errors import DataError, InputError
from opfbench.registry.catalog import get_strategy
from opfbench.registry.references import BASELINE, DEFAULT_FORECAST, DEFAULT_RUN
from opfbench.study import StudyConfig
from opfbench.study.periods import resolve_period
from opfbench.study.run_family import prepare, run_study
from opfbench.study.task_scenarios import chunk_scenario

LOCAL = ("no-action", "llma", "lfma")
HOURS = "2016-06-28T18:00..2016-06-29T02:00"  # evening PV, the night window and midnight


@pytest.fixture(scope="module")
def day_run(tmp_path_factory):
    config = StudyConfig(strategies=LOCAL, ks=(0.0, 0.8), night_modes=("connected", "disconnected"), detail=True)
    return run_study(config, tmp_path_factory.mktemp("day"))


CONFIG_KEYS = ["case", "strategy", "k", "night_mode", "forecast"]
TIMING = ["wall_ms", "solver_ms"]
REFERENCE = ["frontier_kw", "frontier_bound_kw", "frontier_eps_pu"]  # the optimum's, which depends on k


def _repeated_configurations(table: pd.DataFrame) -> set[tuple[tuple, tuple]]:
    """Pairs of configurations whose own rows (every column but the keys, the timings and
    the frontier's reference) are identical."""
    values = [c for c in table.columns if c not in CONFIG_KEYS + TIMING + REFERENCE]
    groups = {key: part[values].reset_index(drop=True) for key, part in table.groupby(CONFIG_KEYS, sort=True)}
    by_hash: dict[int, list[tuple]] = {}
    for key, part in groups.items():
        by_hash.setdefault(int(pd.util.hash_pandas_object(part, index=False).sum()), []).append(key)
    return {(a, b) for keys in by_hash.values() for i, a in enumerate(keys) for b in keys[i + 1 :] if groups[a].equals(groups[b])}


def _no_action_repeats(table: pd.DataFrame) -> set[tuple[tuple, tuple]]:
    """The repeats a grid must have: no action is Q = 0, so neither k nor the "Q at night"
    capability can change it — its rows at every k, connected and connected-q alike, are
    one configuration's (they stay in the grid as each k's and night mode's baseline)."""
    keys = sorted(table[table.strategy == "no-action"].groupby(CONFIG_KEYS).groups)
    same = lambda key: (key[0], key[4], "connected" if key[3] == "connected-q" else key[3])  # noqa: E731
    return {(a, b) for i, a in enumerate(keys) for b in keys[i + 1 :] if same(a) == same(b)}


def test_table_is_tidy_and_complete(day_run):
    table = pd.read_parquet(day_run.out / "steps.parquet")
    # forecast off: 3 rules; oracle: the 2 that read a forecast (no action would repeat its off rows)
    assert len(table) == (3 + 2) * 2 * 2 * 1440  # strategies × k × night modes × steps
    assert set(table[table.forecast == "oracle"].strategy) == {"llma", "lfma"}
    assert _repeated_configurations(table) == _no_action_repeats(table)  # nothing under a forecast repeats
    assert (table.status == "ok").all()
    assert table.groupby(["case", "strategy", "k", "night_mode", "forecast"]).size().eq(1440).all()
    assert table.step_h.eq(1 / 60).all() and table.time.dt.tz is not None
    assert (table.night == (table.time.dt.hour >= 20) | (table.time.dt.hour < 5)).all()
    assert table.solver_ms.isna().all() and (table.certified_by == "").all()
    # wall 0 where a night mode's scenario equals connected's (no PV in the night hours of a 6-hour chunk)
    assert table.wall_ms.ge(0).all() and table.wall_ms[table.night_mode == "connected"].gt(0).all()
    manifest = json.loads((day_run.out / "manifest.json").read_text())
    assert manifest["period"]["steps"] == 1440 and all(t["done"] for t in manifest["tasks"])
    assert manifest["cases"]["paper33"]["ders"][0] == {"name": "PV-10", "bus": 10, "kind": "PV", "rating_mw": 0.6}
    assert manifest["config"]["detail"] is True and (day_run.out / "der_q.parquet").exists()


def test_summary_orders_rules_and_reserve(day_run):
    csv = pd.read_csv(day_run.out / "summary.csv")
    np.testing.assert_allclose(csv.energy_kwh, day_run.summary.energy_kwh, rtol=1e-5)
    s = day_run.summary.set_index(["strategy", "k", "night_mode", "forecast"])
    for k in (0.0, 0.8):
        row = lambda name, k=k: s.loc[(name, k, "connected", "off")]  # noqa: E731
        assert row("lfma").energy_kwh < row("llma").energy_kwh < row("no-action").energy_kwh
        assert row("no-action").savings_pct == pytest.approx(0.0)
        assert row("lfma").no_action_kwh == row("no-action").energy_kwh
    assert s.loc[("lfma", 0.0, "connected", "off")].energy_kwh < s.loc[("lfma", 0.8, "connected", "off")].energy_kwh
    row = s.loc[("no-action", 0.0, "connected", "off")]
    assert row.hours == pytest.approx(24.0) and row.energy_kwh == pytest.approx(row.avg_loss_kw * 24.0)
    assert np.isnan(row.lower_bound_kwh)  # no SOCP in this grid


def test_detail_tables_match_the_steps(day_run):
    steps = pd.read_parquet(day_run.out / "steps.parquet")
    q = pd.read_parquet(day_run.out / "der_q.parquet")
    assert len(q) == len(steps) * 5 and len(pd.read_parquet(day_run.out / "bus_v.parquet")) == len(steps) * 33
    total = q.groupby(["strategy", "k", "night_mode", "forecast", "time"], sort=False).q_mvar.sum().to_numpy()
    np.testing.assert_allclose(total, steps.q_total_mvar.to_numpy(), atol=1e-12)


def _scenario(mode, forecast="off", period=HOURS, forecast_dir="."):
    p = resolve_period(period, "20:00-05:00")
    return p, chunk_scenario("paper33", mode, forecast, p.profiles, p.night, len(p.index), p.index[1] - p.index[0], forecast_dir)


def test_night_modes():
    p, on = _scenario("connected")
    _, off = _scenario("disconnected")
    _, night_q = _scenario("connected-q")
    pv = np.array([kind == "PV" for kind in on.net.der_kinds])
    evening = p.night & (p.index.hour >= 20)
    assert on.der_p_mw[evening][:, pv].sum() > 0 and off.der_p_mw[evening][:, pv].sum() == 0
    np.testing.assert_array_equal(on.der_p_mw[:, ~pv], off.der_p_mw[:, ~pv])
    np.testing.assert_array_equal(on.der_p_mw, night_q.der_p_mw)
    # at night PV units offer √(S̄² − P²) ≈ their rating, by day the usual capability
    dark = p.night & (on.der_p_mw[:, pv].sum(axis=1) == 0)
    assert np.all(on.qmax_mvar()[dark][:, pv] == 0)
    np.testing.assert_allclose(night_q.qmax_mvar()[dark][:, pv], 0.6)
    np.testing.assert_array_equal(night_q.qmax_mvar()[~p.night], on.qmax_mvar()[~p.night])


def test_night_q_lowers_night_losses(tmp_path):
    config = StudyConfig(
        strategies=("lfma",), ks=(0.0,), night_modes=("connected", "connected-q"), forecast=("off",), period=HOURS
    )
    steps = pd.read_parquet(run_study(config, tmp_path).out / "steps.parquet")
    wide = steps.pivot_table(index="time", columns="night_mode", values="losses_kw")
    night = steps.groupby("time").night.first()
    assert (wide["connected-q"][night] < wide["connected"][night] - 1e-3).all()
    # by day the same setpoints (the batched power flow iterates the whole batch: round-off differs)
    np.testing.assert_allclose(wide["connected-q"][~night], wide["connected"][~night], rtol=1e-12)


def test_periods():
    day = resolve_period("paper-day", "sun")
    assert len(day.index) == 1440 and day.step_h == pytest.approx(1 / 60) and "BSRN" in day.sources[1]
    year = resolve_period("year", "20:00-05:00")
    assert len(year.index) == 35136 and year.step_h == 0.25 and "PV3" in year.sources[1]
    assert len(year.chunks("month")) == 12 and len(year.chunks("day")) == 366 and len(year.chunks("6h")) == 4 * 366
    assert [len(range(*c.indices(35136))) for c in year.chunks("month")][:2] == [31 * 96, 29 * 96]
    window = resolve_period("2016-03-01T00:00..2016-03-01T06:00", "sun")
    assert len(window.index) == 24 and window.step_h == 0.25  # outside June: SimBench at 15 min
    for bad in ("tomorrow", "2016-06-28T12:00..2016-06-28T10:00", "2019-01-01..2019-01-02"):
        with pytest.raises(InputError):
            resolve_period(bad, "sun")


def test_chunking_does_not_change_local_rules(tmp_path):
    kw = dict(strategies=LOCAL, ks=(0.4,), night_modes=("disconnected",), period="2016-06-28T22:00..2016-06-29T02:00")
    a = run_study(StudyConfig(chunk="day", **kw), tmp_path / "a")
    b = run_study(StudyConfig(chunk="month", **kw), tmp_path / "b")
    assert len(a.tasks) == 2 * len(b.tasks)
    cols = ["strategy", "forecast", "time"]
    ta = pd.read_parquet(a.out / "steps.parquet").sort_values(cols, kind="stable").drop(columns="wall_ms")
    tb = pd.read_parquet(b.out / "steps.parquet").sort_values(cols, kind="stable").drop(columns="wall_ms")
    # equal up to round-off: the batched power flow iterates a whole chunk together
    pd.testing.assert_frame_equal(ta.reset_index(drop=True), tb.reset_index(drop=True), check_exact=False, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"strategies": ("magic",)}, "unknown strategy"),
        ({"night_modes": ("sometimes",)}, "unknown night mode"),
        ({"ks": ()}, "nothing to run"),
        ({"ks": (1.5,)}, "k must lie"),
        ({"strategies": ("acopf", "socp"), "forecast": ("oracle",)}, "nothing to run"),
        ({"night": "20:00-05:00+09:00"}, "night must be"),
        ({"night": "dusk"}, "night must be"),
        ({"night": "20:00-20:00"}, "night must be"),
        ({"chunk": "year"}, "unknown chunk"),
    ],
)
def test_bad_configuration(kwargs, message):
    with pytest.raises(InputError, match=message):
        StudyConfig(**kwargs)


def test_duplicates_dropped_with_a_note():
    c = StudyConfig.build(ks=[0, 0, 0.2], strategies=["lfma", "lfma"])
    assert c.ks == (0.0, 0.2) and c.strategies == ("lfma",)
    assert any("k values" in n for n in c.notes) and any("strategies" in n for n in c.notes)


def test_missing_model_forecast_is_a_clear_error(tmp_path):
    with pytest.raises(DataError, match="no forecast file"):
        _scenario("connected", "wavelet-cnn-lstm", "paper-day", str(tmp_path))


def _forecast_file(tmp_path, start, end, scale):
    from opfbench.data import load_pv_minute

    pv = load_pv_minute()["pv_ac_kw"].loc[start:end]
    frame = pv.to_frame("actual").assign(mymodel=scale * pv)
    frame.index = frame.index.strftime("%Y-%m-%dT%H:%M:%S%z").rename("timestamp")
    frame.to_csv(tmp_path / "forecast_pv.csv")
    return pv


def test_model_forecast_feeds_algorithm_3_one_step_ahead(tmp_path):
    """A forecast file indexed by target time: P^F at step t is the forecast for t + 1."""
    from opfbench.data import load_pv_minute

    window = _forecast_file(tmp_path, "2016-06-28 00:00", "2016-06-28 23:00", 0.5)  # starts at UTC midnight
    p, sc = _scenario("connected", "mymodel", "paper-day", str(tmp_path))
    index = p.index
    pv_units = np.array([kind == "PV" for kind in sc.net.der_kinds])
    targets = (index + (index[1] - index[0])).tz_convert("UTC")
    ahead = load_pv_minute()["pv_ac_kw"].reindex(targets).to_numpy() / 10.0
    covered = targets >= window.index[0]
    expected = np.where(covered, 0.5 * ahead, p.profiles.pv.to_numpy())  # uncovered night: P^F = P^C (= 0)
    assert (~covered).sum() == 119 and np.all(expected[~covered] == 0)
    np.testing.assert_allclose(sc.der_p_forecast_mw[:, pv_units], expected[:, None] * sc.net.der_rating_mw[pv_units])
    np.testing.assert_array_equal(sc.der_p_forecast_mw[:, ~pv_units], sc.der_p_mw[:, ~pv_units])  # DFIG: P^F = P^C


def test_model_forecast_not_covering_the_day_is_refused(tmp_path):
    _forecast_file(tmp_path, "2016-06-28 03:00", "2016-06-28 12:00", 1.0)
    with pytest.raises(DataError, match="daylight step"):
        _scenario("connected", "mymodel", "paper-day", str(tmp_path))


# ----- the run folder ------------------------------------------------------------------------
SMALL = [
    "run",
    "--period",
    "2016-06-28T10:00..2016-06-28T10:20",
    "--strategies",
    "no-action",
    "lfma",
    "--k",
    "0",
    "--night-modes",
    "connected",
    "--workers",
    "1",
    "--quiet",
]


def test_resume_refuse_fresh(tmp_path, capsys):
    out = str(tmp_path / "run")
    assert main([*SMALL, "--out", out]) == 0
    first = pd.read_parquet(tmp_path / "run" / "steps.parquet")
    assert "(1 run now, 0 kept)" in capsys.readouterr().out
    assert main([*SMALL, "--out", out]) == 0  # everything kept
    assert "(0 run now, 1 kept)" in capsys.readouterr().out
    # nothing left to run: no scheduler is contacted (this address answers nothing)
    on_cluster = [a for a in SMALL if a not in ("--workers", "1")]  # --workers and --scheduler exclude each other
    assert main([*on_cluster, "--out", out, "--scheduler", "tcp://127.0.0.1:9"]) == 0
    assert "(0 run now, 1 kept)" in capsys.readouterr().out
    pd.testing.assert_frame_equal(first, pd.read_parquet(tmp_path / "run" / "steps.parquet"))
    assert main([*SMALL, "--k", "0.2", "--out", out]) == 2
    assert "another configuration (differs in: ks)" in capsys.readouterr().err
    assert main([*SMALL, "--k", "0.2", "--out", out, "--fresh"]) == 0
    assert set(pd.read_parquet(tmp_path / "run" / "steps.parquet").k) == {0.2}


def test_out_and_lock_checks(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main([*SMALL, "--out", str(tmp_path / "file")]) == 2
    assert "not a folder" in capsys.readouterr().err
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / ".lock").write_text(f"{os.getppid()} {os.uname().nodename}\n")  # a live process
    assert main([*SMALL, "--out", str(tmp_path / "busy")]) == 2
    assert "in use by another run" in capsys.readouterr().err
    (tmp_path / "busy" / ".lock").write_text(f"{2**22 + 12345} {os.uname().nodename}\n")  # no such process
    assert main([*SMALL, "--out", str(tmp_path / "busy")]) == 0
    assert not (tmp_path / "busy" / ".lock").exists()


def test_json_without_no_action_has_no_nan(tmp_path, capsys):
    args = [a for a in SMALL if a != "no-action"]
    assert main([*args, "--out", str(tmp_path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]["strategy"] == "lfma" and rows[0]["savings_pct"] is None and rows[0]["no_action_kwh"] is None


def _check_day(table):
    """Per step: the SOCP bound is below every strategy's losses and the AC OPF beats every
    local rule; per configuration: LFMA < LLMA < no action."""
    wide = table.pivot_table(index=["time", "k", "night_mode"], columns="strategy", values="losses_kw")
    bound = table[table.strategy == "acopf"].set_index(["time", "k", "night_mode"])["lower_bound_kw"]
    bound = bound.reindex(wide.index)
    for name in wide.columns:
        assert (bound <= wide[name] + 1e-3).all(), name
        if name not in ("acopf", "acopf-paper", "socp"):
            assert (wide["acopf"] <= wide[name] + 1e-3).all(), name
    energy = table.groupby(["strategy", "k", "night_mode"]).losses_kw.sum()
    for k in table.k.unique():
        for mode in table.night_mode.unique():
            e = energy.xs((k, mode), level=("k", "night_mode"))
            assert e["acopf"] <= e["lfma"] < e["llma"] < e["no-action"]


def test_whole_day_every_strategy_at_k0(tmp_path):
    run = run_study(StudyConfig(ks=(0.0,), night_modes=("connected",), forecast=("off",), detail=False), tmp_path)
    table = pd.read_parquet(run.out / "steps.parquet")
    assert (table.status == "ok").all() and (table.voltage_violation_pu < 1e-6).all()
    _check_day(table)
    s = run.summary.set_index("strategy")
    assert s.loc["acopf", "certified_share"] == 1.0 and s.loc["lfma", "gap_kwh"] > 0
    assert s.loc["acopf", "lower_bound_kwh"] == s.loc["lfma", "lower_bound_kwh"] <= s.loc["acopf", "energy_kwh"]


@pytest.mark.slow
def test_whole_default_grid(tmp_path):
    """The main job's full grid (`opfbench run` defaults): every step solved, orderings hold."""
    config = StudyConfig(forecast_strategies=DEFAULT_FORECAST)
    run = run_study(config, tmp_path, workers=os.cpu_count() or 1)
    table = pd.read_parquet(run.out / "steps.parquet")
    assert (table.status == "ok").all()
    _check_day(table[table.forecast == "off"])
    assert table.groupby(CONFIG_KEYS).ngroups == len(DEFAULT_RUN) * 5 * 3 + len(DEFAULT_FORECAST) * 5 * 3
    # Nothing under a forecast repeats. What does is by definition or by the day's data: no
    # action at every k and Q capability (10 · 9 / 2 + 5 · 4 / 2 pairs); the paper's OPF
    # setup, which equals the AC OPF on this day (the slack never exports and the fast path
    # certifies every step, so neither the slack rule nor the paper's failure rule acts); and
    # a rule at two k whose reduced limit binds nowhere on the day, or whose target at night
    # is 0 so the "Q at night" capability changes nothing (the same strategy and forecast,
    # connected and connected-q alike).
    paper_setup = {
        (("paper33", "acopf", k, mode, "off"), ("paper33", "acopf-paper", k, mode, "off"))
        for k in PAPER_KS
        for mode in ("connected", "connected-q", "disconnected")
    }
    repeats = _repeated_configurations(table) - _no_action_repeats(table) - paper_setup
    assert len(_no_action_repeats(table)) == 55 and _no_action_repeats(table) <= _repeated_configurations(table)
    assert paper_setup <= _repeated_configurations(table)
    night = lambda key: "connected" if key[3] == "connected-q" else key[3]  # noqa: E731
    for a, b in repeats:
        assert a[4] == b[4] == "off" and (a[0], a[1], night(a)) == (b[0], b[1], night(b)), (a, b)


def test_the_repeat_check_finds_a_repeated_configuration(day_run):
    """What the grid ran before the registry's rule: no action under the oracle forecast too."""
    table = pd.read_parquet(day_run.out / "steps.parquet")
    again = table[(table.strategy == "no-action") & (table.forecast == "off")].assign(forecast="oracle")
    extra = _repeated_configurations(pd.concat([table, again])) - _no_action_repeats(table)
    twins = {(key, (*key[:4], "oracle")) for key in table[table.strategy == "no-action"].groupby(CONFIG_KEYS).groups}
    assert twins <= extra and len(twins) == 4


def test_the_default_grid_runs_a_forecast_only_where_a_strategy_reads_it():
    """Planned without running: `opfbench run`'s default grid has 225 configurations (195
    with forecast off: every built-in strategy; 30 with the oracle: the paper's Algorithm 3
    rules, `DEFAULT_FORECAST`); without that choice every strategy the registry says reads a
    forecast runs under the oracle too, and no other."""
    tasks = prepare(StudyConfig(forecast_strategies=DEFAULT_FORECAST)).tasks
    assert {t.runs for t in tasks} == {(("off", DEFAULT_RUN), ("oracle", DEFAULT_FORECAST))}
    configurations = {(t.case, s, t.k, m, f) for t in tasks for f, names in t.runs for s in names for m in t.night_modes}
    assert len(configurations) == 225 and len(tasks) == 5 * 4  # a task runs every forecast source of its (k, chunk)
    every = prepare(StudyConfig()).tasks
    readers = {name for name in DEFAULT_RUN if get_strategy(name).uses_forecast}
    assert {dict(t.runs)["oracle"] for t in every} == {tuple(s for s in DEFAULT_RUN if s in readers)}
    assert BASELINE not in readers and {"llma", "lfma", "volt-var", "cosphi-p"} <= readers


def test_forecast_strategies_must_be_in_the_grid():
    with pytest.raises(InputError, match="forecast strategies volt-var are not among the run's strategies"):
        StudyConfig(strategies=("lfma",), forecast_strategies=("volt-var:curve=b",))


def test_acopf_solver_ipopt_runs_ipopt_on_every_step(tmp_path):
    """--acopf-solver ipopt: no step certified by the SOCP; auto: the same losses, most steps certified."""
    tables = {}
    for solver in ("auto", "ipopt"):
        config = StudyConfig.build(
            strategies=["acopf"],
            ks=[0.0],
            night_modes=["connected"],
            forecast=["off"],
            period="2016-06-28T11:00..2016-06-28T11:20",
            acopf_solver=solver,
        )
        run_study(config, tmp_path / solver, workers=1)
        tables[solver] = pd.read_parquet(tmp_path / solver / "steps.parquet")
    assert set(tables["ipopt"]["certified_by"]) == {"ipopt"}
    assert (tables["auto"]["certified_by"] == "socp").mean() > 0.5
    assert np.allclose(tables["auto"]["losses_kw"], tables["ipopt"]["losses_kw"], rtol=1e-6)


def test_default_detail_is_the_der_q_table_on_short_periods(tmp_path):
    config = StudyConfig(
        strategies=("no-action", "llma"),
        ks=(0.0,),
        night_modes=("connected",),
        forecast=("off",),
        period="2016-06-28T10:00..2016-06-28T11:00",
    )
    run = run_study(config, tmp_path / "run")
    assert run.config.detail_tables == ("der_q",)
    assert len(pd.read_parquet(run.out / "der_q.parquet")) == 2 * 60 * 5 and not (run.out / "bus_v.parquet").exists()
    assert pd.read_parquet(run.out / "der_q.parquet")["strategy"].dtype == object  # text, not categorical


def test_a_night_mode_with_the_same_scenario_takes_the_results_of_the_first(tmp_path):
    """A winter night with no PV output: connected and disconnected are the same scenario,
    so the second mode's rows are the first's (wall time 0); connected-q differs."""
    config = StudyConfig(
        strategies=("no-action", "lfma", "acopf"), ks=(0.2,), forecast=("off",), period="2016-01-10T22:00..2016-01-10T23:00"
    )
    steps = pd.read_parquet(run_study(config, tmp_path / "run").out / "steps.parquet")
    by_mode = {m: g.drop(columns=["night_mode"]).reset_index(drop=True) for m, g in steps.groupby("night_mode")}
    on, off, night_q = by_mode["connected"], by_mode["disconnected"], by_mode["connected-q"]
    pd.testing.assert_frame_equal(on.drop(columns=["wall_ms"]), off.drop(columns=["wall_ms"]), check_exact=True)
    assert (off.wall_ms == 0).all() and (on.wall_ms > 0).all() and (night_q.wall_ms > 0).all()
    assert not np.allclose(on.losses_kw[on.strategy == "acopf"], night_q.losses_kw[night_q.strategy == "acopf"])


def test_auto_chunk_is_six_hours_on_short_periods_and_a_month_otherwise():
    family = prepare(StudyConfig(strategies=("no-action",), ks=(0.0,), night_modes=("connected",), forecast=("off",)))
    day, tasks = family.config, family.tasks
    assert day.chunk == "6h" and [t.start[11:16] for t in tasks] == ["00:00", "06:00", "12:00", "18:00"]
    family = prepare(
        StudyConfig(strategies=("no-action",), ks=(0.0,), night_modes=("connected",), forecast=("off",), period="year")
    )
    year, tasks = family.config, family.tasks
    assert year.chunk == "month" and len(tasks) == 12


def test_curtailed_energy_is_a_column_of_every_strategy(tmp_path):
    """Volt-Watt on a curve that binds at paper33's midday voltages (below 1 p.u.): the steps carry the
    power curtailed (kW), the DER table each unit's (MW), the summary the energy (kWh), and
    a strategy that curtails nothing carries 0."""
    config = StudyConfig(
        strategies=("no-action", "volt-watt:v=0.9/1,p=1/0"),
        ks=(0.0,),
        night_modes=("connected",),
        forecast=("off",),
        period="2016-06-28T11:00..2016-06-28T12:00",
    )
    run = run_study(config, tmp_path)
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    der = pd.read_parquet(tmp_path / "der_q.parquet")
    summary = pd.read_csv(tmp_path / "summary.csv").set_index("strategy")
    vw = "volt-watt:v=0.9/1,p=1/0"
    assert (steps[steps.strategy == "no-action"].curtailed_kw == 0).all()
    assert (steps[steps.strategy == vw].curtailed_kw > 0).any()
    assert summary.loc[vw, "curtailed_kwh"] == pytest.approx((steps[steps.strategy == vw].curtailed_kw / 60).sum(), rel=1e-5)
    assert summary.loc[vw, "curtailed_kwh"] > 0 and summary.loc["no-action", "curtailed_kwh"] == 0
    by_step = der[der.strategy == vw].groupby("time").curtailed_mw.sum() * 1e3
    np.testing.assert_allclose(by_step.to_numpy(), steps[steps.strategy == vw].curtailed_kw.to_numpy(), rtol=1e-12)
    assert run.summary is not None and "curtailed_kwh" in run.summary
    # where it curtails, a rule is compared with the optimum that may curtail; elsewhere with the plain one
    rule = steps[steps.strategy == vw]
    assert (rule.frontier_curtails == (rule.curtailed_kw > 0)).all() and not steps[
        steps.strategy == "no-action"
    ].frontier_curtails.any()
    assert (steps.losses_kw + steps.curtailed_kw >= steps.frontier_kw - 1e-4).all()
    front = pd.read_csv(tmp_path / "frontier.csv")
    assert set(front.curtail) == {False, True} and (front[front.curtail].steps == rule.frontier_curtails.sum()).all()
