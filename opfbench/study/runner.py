"""The study runner: case + day profiles → scenarios → every strategy → one tidy table.

Grid: {strategy} × {k} × {night mode} (× {forecast} for the local rules). Night mode
"connected" keeps PV inverters on the grid at night with whatever small output the data
show; "disconnected" sets PV active power to 0 during the night hours (so they neither
produce nor provide Q). Formulations (AC OPF, SOCP) always see the current P^C; a
forecast only changes the local rules (Algorithm 3).

The per-step table has one row per (configuration, step): time, strategy, k,
night_mode, forecast, status, losses_kw, vmin, vmax, q_total_mvar, excursion_mvar,
lower_bound_kw (NaN where the strategy has none), power_flows.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd

from opfbench.cases import load_case
from opfbench.data import night_mask, night_mask_window, paper_day
from opfbench.errors import DataError, InputError
from opfbench.registry import FORMULATIONS, STRATEGY_NAMES, run_strategy
from opfbench.result import OK, StrategyResult
from opfbench.scenario import Scenario

NIGHT_MODES = ("connected", "disconnected")


@dataclass(frozen=True)
class BenchmarkConfig:
    """What to run. `night` is a clock window "HH:MM-HH:MM" (default the paper's
    "20:00-05:00", which still holds some evening PV output in June) or "sun" (sunset →
    sunrise at the data site, when PV output is zero anyway). `forecast` lists forecast
    sources for Algorithm 3: "off"; "oracle" (P^F = the next step's actual output, an
    upper bound on what a forecaster can give); or a forecasting model's name (e.g.
    "wavelet-cnn-lstm") whose test-part PV forecasts `opfbench forecast --dataset pv
    --out DIR` wrote to `forecast_dir` — PV units then use that model's one-step-ahead
    forecast, the DFIG keeps P^F = P^C (the wind forecaster is trained on the TRY
    series, which does not cover the paper day)."""

    case: str = "paper33"
    strategies: tuple[str, ...] = STRATEGY_NAMES
    ks: tuple[float, ...] = (0.0, 0.2, 0.4, 0.6, 0.8)
    night_modes: tuple[str, ...] = NIGHT_MODES
    night: str = "20:00-05:00"
    forecast: tuple[str, ...] = ("off", "oracle")
    forecast_dir: str = "reports/forecast"

    def __post_init__(self) -> None:
        for name in self.strategies:
            if name not in STRATEGY_NAMES:
                raise InputError(f"unknown strategy {name!r}; choose from {', '.join(STRATEGY_NAMES)}")
        for mode in self.night_modes:
            if mode not in NIGHT_MODES:
                raise InputError(f"unknown night mode {mode!r}; choose from {', '.join(NIGHT_MODES)}")
        if not self.strategies or not self.ks:
            raise InputError("nothing to run: give at least one strategy and one k")


def _night(index: pd.DatetimeIndex, night: str) -> np.ndarray:
    if night == "sun":
        return night_mask(index).to_numpy()
    start, sep, end = night.partition("-")
    if not sep:
        raise InputError(f"night must be 'sun' or a window 'HH:MM-HH:MM', got {night!r}")
    return night_mask_window(index, start, end).to_numpy()


def _model_pv_forecast_pu(config: BenchmarkConfig, model: str, index: pd.DatetimeIndex,
                          pv_now: np.ndarray) -> np.ndarray:
    """P^F per unit for each step t of `index`: the model's forecast for t + 1 step, made
    from data up to t (the forecast file is indexed by target time). Steps the forecast
    file does not cover keep P^F = P^C, but only where P^C and the next step's output are
    0 (night: the test split may start at UTC midnight, after the local day began);
    anywhere else a missing forecast is an error."""
    from opfbench.data import load_pv_minute
    from opfbench.forecasting import load_forecast

    series = load_forecast(config.forecast_dir, "pv", model) / load_pv_minute().attrs["rating_kw"]
    step = index[1] - index[0]
    targets = (index + step).tz_convert("UTC")
    ahead = series.reindex(targets).to_numpy()
    missing = np.isnan(ahead)
    dark = (pv_now == 0) & (np.append(pv_now[1:], pv_now[-1]) == 0)
    if (missing & ~dark).any():
        first = targets[np.flatnonzero(missing & ~dark)[0]]
        raise DataError(f"forecast {model!r} in {config.forecast_dir} has no value for {int((missing & ~dark).sum())} "
                        f"daylight step(s) of the day, first {first}; the forecasts cover "
                        f"{series.index[0]} .. {series.index[-1]}")
    return np.clip(np.where(missing, pv_now, ahead), 0.0, 1.0)


def day_scenarios(config: BenchmarkConfig) -> tuple[pd.DatetimeIndex, dict[tuple[str, str], Scenario]]:
    """The paper day on the configured case, one scenario per (night mode, forecast)."""
    net = load_case(config.case)
    day = paper_day()
    night = _night(day.index, config.night)
    out: dict[tuple[str, str], Scenario] = {}
    for mode in config.night_modes:
        pv = day["pv"].to_numpy() * ~night if mode == "disconnected" else day["pv"].to_numpy()
        wind = day["wind"].to_numpy()
        for source in config.forecast:
            if source == "off":
                out[mode, source] = Scenario.from_profiles(net, day["load"].to_numpy(), pv, wind)
                continue
            if source == "oracle":  # one step ahead, the last step repeats itself
                ahead = np.append(pv[1:], pv[-1]), np.append(wind[1:], wind[-1])
            else:
                pv_f = _model_pv_forecast_pu(config, source, day.index, day["pv"].to_numpy())
                ahead = (pv_f * ~night if mode == "disconnected" else pv_f), wind
            out[mode, source] = Scenario.from_profiles(net, day["load"].to_numpy(), pv, wind, *ahead)
    return day.index, out


def _rows(index: pd.DatetimeIndex, res: StrategyResult, mode: str, source: str) -> pd.DataFrame:
    lb = res.lower_bound_kw if res.lower_bound_kw is not None else np.full(res.n_snapshots, np.nan)
    return pd.DataFrame({
        "time": index, "strategy": res.strategy, "k": res.k, "night_mode": mode, "forecast": source,
        "status": res.status.astype(str), "losses_kw": res.losses_kw, "vmin": res.vmin, "vmax": res.vmax,
        "voltage_violation": res.voltage_violation(), "q_total_mvar": res.q_mvar.sum(axis=1),
        "excursion_mvar": res.excursion_mvar, "lower_bound_kw": lb, "power_flows": res.power_flows,
    })


def run_benchmark(config: BenchmarkConfig, progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """Run the grid; returns the tidy per-step table (see the module docstring)."""
    say = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    index, scenarios = day_scenarios(config)
    jobs = [(name, k, mode, source) for (mode, source) in scenarios for name in config.strategies
            for k in config.ks if source == "off" or name not in FORMULATIONS]
    frames = []
    for i, (name, k, mode, source) in enumerate(jobs, start=1):
        t0 = time.perf_counter()
        res = run_strategy(name, scenarios[mode, source], k)
        frames.append(_rows(index, res, mode, source))
        failed = int((res.status != OK).sum())
        say(f"[{i}/{len(jobs)}] {name:<9} k={k:<4g} night {mode:<12} forecast {source:<6} "
            f"{np.nansum(res.losses_kw) / 60:8.2f} kWh  {failed:4d} not ok  {time.perf_counter() - t0:6.1f} s")
    return pd.concat(frames, ignore_index=True)


def summarize(table: pd.DataFrame) -> pd.DataFrame:
    """Per configuration: average losses (kW), energy (kWh, over the steps' duration),
    savings vs no action under the same k/night/forecast (%), steps not "ok", steps
    with a voltage violation > 1e-6 p.u., largest capability excursion (MVAr) and the
    average gap to the SOCP lower bound where one was computed (kW)."""
    times = np.sort(table["time"].unique())
    step_h = float(np.min(np.diff(times)) / np.timedelta64(1, "h")) if len(times) > 1 else 1 / 60
    keys = ["strategy", "k", "night_mode", "forecast"]
    g = table.groupby(keys, sort=False)
    out = pd.DataFrame({
        "avg_loss_kw": g["losses_kw"].mean(),
        "energy_kwh": g["losses_kw"].sum() * step_h,
        "not_ok_steps": g["status"].apply(lambda s: int((s != OK).sum())),
        "voltage_violation_steps": g["voltage_violation"].apply(lambda s: int((s > 1e-6).sum())),
        "max_excursion_mvar": g["excursion_mvar"].max(),
    }).reset_index()
    base = out[out.strategy == "no-action"].drop(columns="strategy").set_index(["k", "night_mode", "forecast"])
    ref = out.join(base["energy_kwh"].rename("no_action_kwh"), on=["k", "night_mode", "forecast"])
    out["savings_pct"] = 100 * (1 - ref["energy_kwh"] / ref["no_action_kwh"])
    return out
