"""A chunk's profiles → the Scenario of one (case, night mode, forecast).

The chunk carries one step beyond its end when the period has one (`ahead` rows), so the
oracle forecast (P^F at t = the actual output at t + 1 step) is the same whatever the
chunking; at the period's last step the forecast repeats the current output.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.cases import load_case
from opfbench.errors import DataError
from opfbench.scenario import Scenario


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
    return np.clip(np.where(missing, pv_now[:n], ahead), 0.0, 1.0)


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
    net = load_case(case)
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
