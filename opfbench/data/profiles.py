"""Per-unit profiles for a simulation window, and the paper's day.

Mapping rule of a case's units to the profiles (`assemble_profiles`):

* ``load`` — every load of the case follows one load profile (default: SimBench
  aggregated semi-urban MV load P), scaled so that its peak *within the requested
  window* is 1.0; multiply it onto the case's nominal P and Q (constant power factor).
  For a one-day window the day's peak load equals the nominal load.
* ``pv`` — every PV unit follows the PV profile, per unit of its rating, in [0, 1]:
  SimBench PV3 (year 2016) or the BSRN-driven 10 kW plant (June 2016, 1 min).
* ``wind`` — the DFIG follows the wind profile SimBench WP4, per unit of its rating.

Profiles reach the run's step (1 min or 15 min) by linear interpolation in time
between the source's samples (15 min → 1 min: straight lines between quarter
hours; 1 min → 15 min: the value at each quarter hour). Windows outside a source's
span are refused, not extrapolated.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pandas as pd

from opfbench.data.loaders import load_pv_minute, load_simbench_profiles
from opfbench.data.sites import PAYERNE
from opfbench.errors import InputError

#: The paper's simulated day: a local date (Payerne, Europe/Zurich) in the last 10 % of
#: June 2016 — clear morning, broken cloud from mid-afternoon (strong PV ramps),
#: moderate wind. The forecasting test split (last 10 % of the month) contains it.
PAPER_DAY = "2016-06-28"
PAPER_DAY_TZ = PAYERNE.tz
#: Load profile name -> column of `load_simbench_profiles` (active power).
LOAD_PROFILE_COLUMNS = {"mv_semiurb": "mv_semiurb_p_pu", "h0a": "h0a_p_pu", "g0a": "g0a_p_pu"}
#: Weather columns of the PV data carried into `paper_day`.
PAPER_DAY_WEATHER = ("ghi_wm2", "dni_wm2", "dhi_wm2", "temp_air_c", "relative_humidity_pct", "pressure_hpa")

PvSource = Literal["simbench", "bsrn"]  # the PV profile: SimBench PV3 or the BSRN plant


def interpolate_to(series: pd.Series, index: pd.DatetimeIndex) -> np.ndarray:
    """Values of ``series`` (tz-aware index) at the instants of ``index`` by linear
    interpolation in time; `InputError` if ``index`` leaves the series' span."""
    if index[0] < series.index[0] or index[-1] > series.index[-1]:
        raise InputError(
            f"window {index[0]} .. {index[-1]} leaves the span of profile {series.name!r} "
            f"({series.index[0]} .. {series.index[-1]})"
        )
    origin = series.index.as_unit("ns").asi8[0]
    x = (index.as_unit("ns").asi8 - origin) / 1e9
    xp = (series.index.as_unit("ns").asi8 - origin) / 1e9
    return np.interp(x, xp, series.to_numpy(dtype=float))


def _check_window(index: pd.DatetimeIndex) -> None:
    if not isinstance(index, pd.DatetimeIndex) or index.tz is None or len(index) == 0:
        raise InputError("the window must be a non-empty, time-zone-aware DatetimeIndex")
    if not index.is_monotonic_increasing or index.has_duplicates:
        raise InputError("the window's times must be strictly increasing")


def assemble_profiles(
    index: pd.DatetimeIndex, load_profile: str = "mv_semiurb", pv_source: PvSource = "simbench"
) -> pd.DataFrame:
    """Per-unit multipliers ``load``, ``pv``, ``wind`` on ``index`` (see the module
    docstring for the mapping rule). ``load_profile`` is a key of
    `LOAD_PROFILE_COLUMNS`; ``pv_source`` picks SimBench PV3 or the BSRN plant."""
    _check_window(index)
    if load_profile not in LOAD_PROFILE_COLUMNS:
        raise InputError(f"unknown load profile {load_profile!r}; choose from {sorted(LOAD_PROFILE_COLUMNS)}")
    simbench = load_simbench_profiles()
    load = interpolate_to(simbench[LOAD_PROFILE_COLUMNS[load_profile]], index)
    if load.max() <= 0:
        raise InputError(f"load profile {load_profile!r} has no positive value in the window")
    if pv_source == "simbench":
        pv = interpolate_to(simbench["pv_pu"], index)
    elif pv_source == "bsrn":
        minute = load_pv_minute()
        pv = interpolate_to(minute["pv_ac_kw"] / minute.attrs["rating_kw"], index)
    else:
        raise InputError(f"unknown pv_source {pv_source!r}; choose 'simbench' or 'bsrn'")
    wind = interpolate_to(simbench["wind_pu"], index)
    out = pd.DataFrame({"load": load / load.max(), "pv": pv, "wind": wind}, index=index)
    out.attrs = {
        "units": dict.fromkeys(out.columns, "p.u."),
        "load_profile": simbench.attrs["profiles"][LOAD_PROFILE_COLUMNS[load_profile]],
        "pv_profile": simbench.attrs["profiles"]["pv_pu"] if pv_source == "simbench" else "BSRN Payerne 10 kW plant",
        "wind_profile": simbench.attrs["profiles"]["wind_pu"],
    }
    return out


def paper_day() -> pd.DataFrame:
    """The paper's day `PAPER_DAY`: 1440 one-minute steps from local midnight
    (Europe/Zurich). Columns ``load``, ``pv``, ``wind`` (p.u., as `assemble_profiles`
    with PV from the BSRN-driven plant) plus the measured weather of that minute
    (``ghi_wm2`` … ``pressure_hpa``, units as `load_pv_minute`)."""
    index = pd.date_range(PAPER_DAY, periods=1440, freq="1min", tz=PAPER_DAY_TZ)
    out = assemble_profiles(index, pv_source="bsrn")
    minute = load_pv_minute()
    weather = minute[list(PAPER_DAY_WEATHER)].reindex(index.tz_convert("UTC")).set_axis(index)
    attrs = {**out.attrs, "date": PAPER_DAY, "tz": PAPER_DAY_TZ}
    attrs["units"] |= {col: minute.attrs["units"][col] for col in PAPER_DAY_WEATHER}
    out = out.join(weather)
    out.attrs = attrs
    return out
