"""The period of a study: its steps (local time, Europe/Zurich — the data site), the
per-unit profiles on them, the night hours, and its split into chunks.

- `paper-day` (default): the paper's day, 1440 × 1 min, PV from the BSRN-driven 10 kW
  plant at Payerne (`opfbench.data.paper_day`).
- `year`: 2016 at SimBench's native 15 min (35 136 steps), PV = SimBench PV3, wind =
  SimBench WP4, load = SimBench semi-urban MV load. With `step_minutes` (e.g. 1) the
  profiles are interpolated linearly between quarter hours, up to the last one
  (2016-12-31 23:45; 527 026 steps at 1 min).
- `START..END` (local times, END excluded, e.g. `2016-06-28T10:00..2016-06-28T12:00`):
  1-min steps with the BSRN plant's PV when the window lies in June 2016 (the BSRN month),
  otherwise 15-min steps with SimBench PV3; `step_minutes` overrides the step.

Cases with their own time series (SimBench grids: per-load and per-DER profiles of 2016
at 15 min) run at their native step (`native_minutes`): `paper-day` is that date at
15 min, `year` and `START..END` the same instants at 15 min, unless `step_minutes` is
given (then their profiles are interpolated linearly in time too). Their scenarios take
the case's own series at the period's instants (`opfbench.study.scenarios`); the period's
load/pv/wind profiles are only for cases without a series.

Profiles follow the mapping rule of `opfbench.data.assemble_profiles` on the whole period
(the load's peak within the period = the nominal load), computed once; a task receives
its chunk's slice plus the next step (for the oracle forecast), so results do not depend
on how the period is chunked or on the number of workers. Chunks are local calendar days,
ISO weeks or months.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.data import PAPER_DAY, assemble_profiles, load_pv_minute, night_mask, night_mask_window
from opfbench.data.profiles import PAPER_DAY_TZ
from opfbench.errors import InputError

YEAR = "2016"
_CHUNK_FREQ = {"day": "D", "week": "W", "month": "M"}
CHUNK_6H = "6h"


@dataclass(frozen=True)
class Period:
    """Steps `index` (tz-aware), per-unit `profiles` (load, pv, wind) and `night` (bool)
    on it; `step_h` the step length in hours; `pv_profile` names the PV source."""

    label: str
    profiles: pd.DataFrame
    night: np.ndarray
    step_h: float
    sources: tuple[str, ...]

    @property
    def index(self) -> pd.DatetimeIndex:
        return self.profiles.index

    def chunks(self, chunk: str) -> list[slice]:
        """Consecutive slices of the steps, one per local quarter day (00-06-12-18 h), day,
        week or month."""
        local = self.index.tz_localize(None)
        keys = local.floor(CHUNK_6H).asi8 if chunk == CHUNK_6H else local.to_period(_CHUNK_FREQ[chunk]).asi8
        cuts = np.flatnonzero(np.diff(keys)) + 1
        bounds = [0, *cuts.tolist(), len(keys)]
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def as_dict(self) -> dict:
        return {
            "start": self.index[0].isoformat(),
            "end": self.index[-1].isoformat(),
            "steps": len(self.index),
            "step_h": self.step_h,
        }


def local_time(text: str) -> pd.Timestamp:
    """`text` as an instant: a time without offset is local time (Europe/Zurich — the same
    clock as SimBench's Europe/Berlin, CET/CEST); one in the hour daylight saving skips,
    or in the hour it repeats (give the offset then, e.g. 2016-10-30T02:30+02:00), is
    refused."""
    try:
        ts = pd.Timestamp(text)
    except (ValueError, TypeError) as exc:
        raise InputError(f"cannot read time {text!r} (use e.g. 2016-06-28T10:00)") from exc
    if ts is pd.NaT:
        raise InputError(f"cannot read time {text!r} (use e.g. 2016-06-28T10:00)")
    if ts.tzinfo is not None:
        return ts.tz_convert(PAPER_DAY_TZ)
    try:
        return ts.tz_localize(PAPER_DAY_TZ, ambiguous="raise", nonexistent="raise")
    except ValueError as exc:  # pytz/zoneinfo's ambiguous and non-existent time errors
        raise InputError(
            f"time {text!r} is skipped or repeated by the daylight-saving change in local time ({type(exc).__name__}); "
            "give its UTC offset, e.g. 2016-10-30T02:30+02:00"
        ) from None


def _window(period: str, step_minutes: float | None, native_minutes: float | None) -> tuple[pd.DatetimeIndex, str]:
    if period == "paper-day":
        minutes = step_minutes or native_minutes or 1
        return pd.date_range(
            PAPER_DAY, periods=int(round(1440 / minutes)), freq=pd.Timedelta(minutes=minutes), tz=PAPER_DAY_TZ
        ), "bsrn"
    if period == "year":  # up to SimBench's last quarter hour (no extrapolation at finer steps)
        start = pd.Timestamp(f"{YEAR}-01-01", tz=PAPER_DAY_TZ)
        last = pd.Timestamp(f"{YEAR}-12-31 23:45", tz=PAPER_DAY_TZ)
        return pd.date_range(start, last, freq=pd.Timedelta(minutes=step_minutes or 15)), "simbench"
    first, sep, last = period.partition("..")
    if not sep:
        raise InputError(f"period must be 'paper-day', 'year' or 'START..END', got {period!r}")
    start, end = local_time(first), local_time(last)
    if end <= start:
        raise InputError(f"period {period!r}: END must come after START")
    bsrn = load_pv_minute().index
    inside = start >= bsrn[0] and end <= bsrn[-1] + pd.Timedelta(minutes=1)
    step = pd.Timedelta(minutes=step_minutes or native_minutes or (1 if inside else 15))
    index = pd.date_range(start, end, freq=step, inclusive="left")
    if len(index) < 1:
        raise InputError(f"period {period!r} holds no step of {step}")
    return index, "bsrn" if inside else "simbench"


def _night(index: pd.DatetimeIndex, night: str) -> np.ndarray:
    if night == "sun":
        return night_mask(index).to_numpy()
    start, _, end = night.partition("-")
    return night_mask_window(index, start, end).to_numpy()


def period_index(period: str, step_minutes: float | None = None, native_minutes: float | None = None) -> pd.DatetimeIndex:
    """The steps of `period` alone (no profiles), as `resolve_period` takes them."""
    return _window(period, step_minutes, native_minutes)[0]


def resolve_period(period: str, night: str, step_minutes: float | None = None, native_minutes: float | None = None) -> Period:
    """The period's steps, profiles and night mask (InputError for unknown periods or
    windows outside the data); `native_minutes`: the step of the cases' own series."""
    if step_minutes is not None and not step_minutes > 0:
        raise InputError(f"step must be a positive number of minutes, got {step_minutes}")
    if period == "paper-day" and (step_minutes or native_minutes or 1) > 1440:
        raise InputError(f"step must be at most a day on the paper day, got {step_minutes} minutes")
    index, pv_source = _window(period, step_minutes, native_minutes)
    profiles = assemble_profiles(index, pv_source=pv_source)
    step_h = float((index[1] - index[0]) / pd.Timedelta(hours=1)) if len(index) > 1 else (step_minutes or 1) / 60
    sources = (profiles.attrs["load_profile"], profiles.attrs["pv_profile"], profiles.attrs["wind_profile"])
    return Period(period, profiles, _night(index, night), step_h, sources)
