"""A chunk's profiles → the Scenario of one (case, night mode, forecast).

The chunk carries one step beyond its end when the period has one (`ahead` rows), so the
oracle forecast (P^F at t = the actual output at t + 1 step) is the same whatever the
chunking; at the period's last step the forecast repeats the current output.

A case with its own time series (a SimBench grid) takes every load's P and Q and every
DER's P from its series at the chunk's instants (the worker loads the case by spec,
cached per process); the chunk's load/pv/wind profiles only give the instants then. Night
modes act on its solar units as on the paper's PV. `check_cases` refuses, before any
work, what such a case cannot run: a model's forecasts (they forecast the BSRN plant of
the paper day, not the grid's own units).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Sequence

import numpy as np
import pandas as pd

from opfbench.errors import DataError, InputError
from opfbench.io import Case, load_case
from opfbench.scenario import Scenario

if TYPE_CHECKING:
    from opfbench.study.periods import Period


def model_pv_forecast_pu(
    forecast_dir: str, model: str, index: pd.DatetimeIndex, pv_now: np.ndarray, step: pd.Timedelta
) -> np.ndarray:
    """P^F per unit for each step t of `index`: the model's forecast for t + 1 step, made
    from data up to t (the forecast file is indexed by target time). Steps the forecast
    file does not cover keep P^F = P^C, but only where P^C and the next step's output are
    0 (night: the test split may start at UTC midnight, after the local day began);
    anywhere else a missing forecast is an error. `pv_now` has one value per step of
    `index` plus, when the period goes on, the next step's."""
    from opfbench.data import load_pv_minute
    from opfbench.forecasting.outputs import load_forecast

    series = load_forecast(forecast_dir, "pv", model) / load_pv_minute().attrs["rating_kw"]
    n = len(index)
    targets = (index + step).tz_convert("UTC")
    ahead = series.reindex(targets).to_numpy()
    missing = np.isnan(ahead)
    nxt = pv_now[1 : n + 1] if len(pv_now) > n else np.append(pv_now[1:n], pv_now[n - 1])
    dark = (pv_now[:n] == 0) & (nxt == 0)
    if (missing & ~dark).any():
        first = targets[np.flatnonzero(missing & ~dark)[0]]
        raise DataError(
            f"forecast {model!r} in {forecast_dir} has no value for {int((missing & ~dark).sum())} "
            f"daylight step(s) of the period, first {first}; the forecasts cover "
            f"{series.index[0]} .. {series.index[-1]}"
        )
    return np.where(missing, pv_now[:n], ahead)  # in [0, 1]: `load_forecast` refuses values outside the rating


def check_model_forecasts(forecast_dir: str, models: Sequence[str], period: Period) -> None:
    """Refuse, before any work, a model whose forecast file is unreadable, out of range or
    leaves a daylight step of the period uncovered: `model_pv_forecast_pu`, the rule each
    chunk applies, applied once to the whole period (the chunks' steps and next steps are
    the period's, so no chunk can fail later)."""
    pv = period.profiles["pv"].to_numpy()
    for model in models:
        model_pv_forecast_pu(forecast_dir, model, period.index, pv, pd.Timedelta(hours=period.step_h))


def chunk_scenario(
    case: str,
    night_mode: str,
    forecast: str,
    profiles: pd.DataFrame,
    night: np.ndarray,
    n_steps: int,
    step: pd.Timedelta,
    forecast_dir: str,
) -> Scenario:
    """The scenario of the first `n_steps` rows of `profiles` (load, pv, wind p.u.; a
    further row, if present, is the next step). Night mode "disconnected" zeroes PV
    output (and its forecast) in the night hours; "connected-q" gives PV units the
    S-limited capability there."""
    own = load_case(case)
    if own.series is not None:
        return _series_scenario(own, night_mode, forecast, profiles.index, night, n_steps)
    net = own.balanced("a study")
    load, pv_all, wind_all = (profiles[c].to_numpy() for c in ("load", "pv", "wind"))
    pv_all = pv_all * ~night if night_mode == "disconnected" else pv_all
    pv, wind = pv_all[:n_steps], wind_all[:n_steps]
    ahead_pv = ahead_wind = None
    if forecast == "oracle":
        ahead_pv, ahead_wind = (np.append(x[1 : n_steps + 1], x[len(x) - 1])[:n_steps] for x in (pv_all, wind_all))
    elif forecast != "off":
        raw = profiles["pv"].to_numpy()
        ahead_pv = model_pv_forecast_pu(forecast_dir, forecast, profiles.index[:n_steps], raw, step)
        ahead_pv = ahead_pv * ~night[:n_steps] if night_mode == "disconnected" else ahead_pv
        ahead_wind = wind
    scenario = Scenario.from_profiles(net, load[:n_steps], pv, wind, ahead_pv, ahead_wind)
    if night_mode == "connected-q":
        scenario = scenario.with_night_q(night[:n_steps])
    return scenario


def _series_scenario(
    case: Case, night_mode: str, forecast: str, times: pd.DatetimeIndex, night: np.ndarray, n_steps: int
) -> Scenario:
    """The scenario of a case's own series at the first `n_steps` of `times` (a further
    instant, if present, is the next step, for the oracle); night modes on its solar units."""
    load_p, load_q, der_p = case.series.rows(times) if case.series is not None else (None, None, None)
    assert load_p is not None and load_q is not None and der_p is not None
    net = case.balanced("a study")
    if night_mode == "disconnected":
        der_p = np.where(night[:, None] & net.der_solar[None, :], 0.0, der_p)
    ahead = None
    if forecast == "oracle":
        ahead = np.vstack([der_p[1 : n_steps + 1], der_p[len(der_p) - 1 :]])[:n_steps]
    scenario = Scenario.from_series(net, load_p[:n_steps], load_q[:n_steps], der_p[:n_steps], ahead)
    if night_mode == "connected-q":
        scenario = scenario.with_night_q(night[:n_steps])
    return scenario


@dataclass(frozen=True)
class SharedSnapshots:
    """The distinct snapshots of several scenarios of one chunk (its night modes): `union`
    holds each snapshot once — all of the first scenario's, then each later one's that no
    earlier scenario has at the same step (`Scenario.same_rows`) —, `rows[j]` where
    scenario j's snapshots are in it, `owned[j]` how many of them scenario j brought. A
    snapshot-wise strategy runs once on `union`; each scenario takes its rows."""

    union: Scenario
    rows: tuple[np.ndarray, ...]
    owned: tuple[int, ...]

    @classmethod
    def of(cls, scenarios: Sequence[Scenario]) -> "SharedSnapshots":
        rows: list[np.ndarray] = []
        parts: list[tuple[Scenario, np.ndarray]] = []
        size = 0
        for j, scenario in enumerate(scenarios):
            where = np.full(scenario.n_snapshots, -1)
            for earlier, at in zip(scenarios[:j], rows, strict=False):
                same = (where < 0) & scenario.same_rows(earlier)
                where[same] = at[same]
            fresh = np.flatnonzero(where < 0)
            where[fresh] = size + np.arange(fresh.size)
            size += fresh.size
            rows.append(where)
            parts.append((scenario, fresh))
        return cls(Scenario.union([p for p in parts if p[1].size]), tuple(rows), tuple(p[1].size for p in parts))

    def share(self, j: int) -> float:
        """The part of a union run's wall time scenario j is charged: the snapshots it brought."""
        return self.owned[j] / self.union.n_snapshots


@dataclass(frozen=True)
class CaseCheck:
    """What `check_cases` found: the native step of the cases' own series (minutes, None
    when no case has one), whether some cases have none, the series' sources, and the
    cases' notes (one line each)."""

    native_minutes: float | None
    mixed: bool
    sources: tuple[str, ...]
    notes: tuple[str, ...]


def check_cases(cases: tuple[str, ...], forecasts: tuple[str, ...]) -> CaseCheck:
    """Load every case (InputError & co. for a bad spec) and refuse a model's forecast on
    a case with its own series (the models forecast the BSRN plant of the paper day)."""
    loaded = [load_case(c) for c in cases]
    own = [c.series for c in loaded if c.series is not None]
    steps = {series.step / pd.Timedelta(minutes=1) for series in own}
    if len(steps) > 1:
        raise InputError(f"the cases' own series have different steps ({sorted(steps)} min): run them separately")
    models = [f for f in forecasts if f not in ("off", "oracle")]
    if own and models:
        spec = next(c.spec for c in loaded if c.series is not None)
        raise InputError(
            f"forecast {models[0]!r}: the models' forecasts are of the BSRN Payerne PV plant (the paper day's data), "
            f"not of {spec}'s own units; use --forecast off oracle on cases with their own profiles"
        )
    notes = tuple(f"note: {c.spec}: {n}" for c in loaded for n in c.notes)
    sources = tuple(dict.fromkeys(series.source for series in own))
    return CaseCheck(steps.pop() if steps else None, bool(own) and len(own) < len(loaded), sources, notes)


def study_period(cases: tuple[str, ...], forecasts: tuple[str, ...], period: str, night: str, step_minutes: float | None):
    """(Period, CaseCheck) of a study: the period at the cases' native step when they have
    their own series (SimBench's span is the period's data span, 2016); cases with and
    without their own series together only where both give the same instants (e.g. the
    year, or with --step-minutes)."""
    from opfbench.study.periods import period_index, resolve_period

    check = check_cases(cases, forecasts)
    index = period_index(period, step_minutes, check.native_minutes)
    if check.mixed and not period_index(period, step_minutes).equals(index):
        raise InputError(
            f"period {period!r}: cases with their own profiles (simbench:…) run at their {check.native_minutes:g}-min steps, "
            "the others at the period's own step (the paper day: 1 min); give --step-minutes (e.g. 15) to run them "
            "together, or run them separately"
        )
    resolved = resolve_period(period, night, step_minutes, check.native_minutes)
    return replace(resolved, sources=resolved.sources + check.sources), check
