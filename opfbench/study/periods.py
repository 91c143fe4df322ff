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
the case's own series at the period's instants (`opfbench.study.task_scenarios`); the period's
load/pv/wind profiles are only for cases without a series.

Profiles follow the mapping rule of `opfbench.data.assemble_profiles` on the whole period
(the load's peak within the period = the nominal load), computed once; a task receives
its chunk's slice plus the next step (for the oracle forecast), so results do not depend
on how the period is chunked or on the number of workers. Chunks are local calendar days,
ISO weeks or months.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime

import numpy as np
import pandas as pd

from opfbench.data import PAPER_DAY, assemble_profiles, load_pv_minute, night_mask, night_mask_window
from opfbench.data.profiles import PAPER_DAY_TZ, PvSource
from opfbench.errors import InputError

YEAR = "2016"
_CHUNK_FREQ = {"day": "D", "week": "W", "month": "M"}
CHUNK_6H = "6h"
MIN_STEP_MINUTES = 1.0  # the finest data: BSRN's 1-minute PV
MAX_STEP_MINUTES = 1e7  # beyond any period of the data (a year is 527 040 min); larger overflows a Timedelta


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


def local_time(text: str, label: str = "period") -> pd.Timestamp:
    """An ISO 8601 date or date-time (local time, or with its UTC offset) as a time in
    `PAPER_DAY_TZ` (the same clock as SimBench's Europe/Berlin); InputError naming `label`
    for anything else (01/06/2016 is read one way by some and the other way by others, so
    it is not read at all) and for local times the daylight-saving change skips or repeats."""
    try:
        parsed = datetime.fromisoformat(text.strip())
    except ValueError:
        raise InputError(
            f"{label}: cannot read time {text!r}: give an ISO 8601 date or date-time, e.g. 2016-06-28 or "
            "2016-06-28T10:00 (local time) or 2016-06-28T10:00+02:00"
        ) from None
    first_step, last_step = _data_span()
    if not first_step.year <= parsed.year <= last_step.year + 1:  # before localizing: a zone's rules of year 1 are not 2016's
        raise InputError(
            f"{label}: {text} lies outside the data, which cover {first_step.isoformat()} .. "
            f"{(last_step + pd.Timedelta(minutes=15)).isoformat()}"
        )
    ts = pd.Timestamp(parsed)
    if ts.tzinfo is not None:
        return ts.tz_convert(PAPER_DAY_TZ)
    local = ts.tz_localize(PAPER_DAY_TZ, ambiguous="NaT", nonexistent="NaT")
    if local is pd.NaT:
        first = ts.tz_localize(PAPER_DAY_TZ, ambiguous=True, nonexistent="NaT")
        if first is pd.NaT:
            raise InputError(
                f"{label}: {text} does not exist in {PAPER_DAY_TZ}: the clocks skip that hour when summer time "
                "begins; give a time outside it, or with its UTC offset (e.g. +01:00)"
            )
        second = ts.tz_localize(PAPER_DAY_TZ, ambiguous=False)
        raise InputError(
            f"{label}: {text} occurs twice in {PAPER_DAY_TZ} (the clocks go back when summer time ends); "
            f"add the offset: {first.isoformat()} (the first) or {second.isoformat()} (the second)"
        )
    return local


def _data_span() -> tuple[pd.Timestamp, pd.Timestamp]:
    """(first, last) time of the year's data (SimBench's quarter hours of 2016, local)."""
    return pd.Timestamp(f"{YEAR}-01-01", tz=PAPER_DAY_TZ), pd.Timestamp(f"{YEAR}-12-31 23:45", tz=PAPER_DAY_TZ)


def _steps(label: str, start: pd.Timestamp, end: pd.Timestamp, step_minutes: float) -> tuple[pd.DatetimeIndex, float]:
    """(steps from `start` up to `end` excluded, the step in hours); InputError when the
    step is below the data's finest (1 min) or longer than the period."""
    step = pd.Timedelta(minutes=step_minutes) if step_minutes <= MAX_STEP_MINUTES else None
    if step_minutes < MIN_STEP_MINUTES:
        raise InputError(
            f"--step-minutes {step_minutes:g}: the finest data (BSRN PV) are 1-minute values; the step must be ≥ "
            f"{MIN_STEP_MINUTES:g} min"
        )
    if step is None or step > end - start:
        length = (end - start) / pd.Timedelta(minutes=1)
        raise InputError(f"period {label!r} lasts {length:g} min, less than one step of {step_minutes:g} min (--step-minutes)")
    return pd.date_range(start, end, freq=step, inclusive="left"), step / pd.Timedelta(hours=1)


def _window(period: str, step_minutes: float | None, native_minutes: float | None) -> tuple[pd.DatetimeIndex, float, PvSource]:
    """(steps, step in hours, PV source) of `period`; `native_minutes` the default step of
    the cases' own series (None: the period's own default)."""
    if period == "paper-day":
        start = pd.Timestamp(PAPER_DAY, tz=PAPER_DAY_TZ)
        return *_steps(period, start, start + pd.DateOffset(days=1), step_minutes or native_minutes or 1), "bsrn"
    first_step, last_step = _data_span()
    if period == "year":  # up to SimBench's last quarter hour (no extrapolation at finer steps)
        index, step_h = _steps(period, first_step, last_step + pd.Timedelta(minutes=15), step_minutes or native_minutes or 15)
        return index[index <= last_step], step_h, "simbench"
    first, sep, last = period.partition("..")
    if not sep:
        raise InputError(f"period must be 'paper-day', 'year' or 'START..END', got {period!r}")
    start, end = local_time(first), local_time(last)
    if end <= start:
        raise InputError(f"period {period!r}: END must come after START")
    if start < first_step or end > last_step + pd.Timedelta(minutes=15):
        raise InputError(
            f"period {period!r} leaves the data: they cover {first_step.isoformat()} .. "
            f"{(last_step + pd.Timedelta(minutes=15)).isoformat()} (SimBench 2016, END excluded)"
        )
    bsrn = load_pv_minute().index
    inside = start >= bsrn[0] and end <= bsrn[-1] + pd.Timedelta(minutes=1)
    index, step_h = _steps(period, start, end, step_minutes or native_minutes or (1 if inside else 15))
    if index[-1] > last_step:
        raise InputError(
            f"period {period!r}: its last step {index[-1].isoformat()} lies after the data's last, {last_step.isoformat()}"
        )
    return index, step_h, "bsrn" if inside else "simbench"


def _night(index: pd.DatetimeIndex, night: str) -> np.ndarray:
    if night == "sun":
        return night_mask(index).to_numpy()
    start, _, end = night.partition("-")
    return night_mask_window(index, start, end).to_numpy()


def _check_step(step_minutes: float | None) -> None:
    """None (the period's own step) or a finite number of minutes > 0 (0 is no step, and
    must not read as "not given")."""
    number = isinstance(step_minutes, (int, float)) and not isinstance(step_minutes, bool)
    if step_minutes is not None and not (number and math.isfinite(step_minutes) and step_minutes > 0):
        raise InputError(f"--step-minutes must be a finite number of minutes > 0, got {step_minutes!r}")


def period_index(period: str, step_minutes: float | None = None, native_minutes: float | None = None) -> pd.DatetimeIndex:
    """The steps of `period` alone (no profiles), as `resolve_period` takes them."""
    _check_step(step_minutes)
    return _window(period, step_minutes, native_minutes)[0]


def resolve_period(period: str, night: str, step_minutes: float | None = None, native_minutes: float | None = None) -> Period:
    """The period's steps, profiles and night mask (InputError for unknown periods, times
    that are not ISO 8601 or fall in a daylight-saving change, windows outside the data,
    a step below 1 min or longer than the period); `native_minutes`: the default step of
    the cases' own series."""
    _check_step(step_minutes)
    index, step_h, pv_source = _window(period, step_minutes, native_minutes)
    profiles = assemble_profiles(index, pv_source=pv_source)
    sources = (profiles.attrs["load_profile"], profiles.attrs["pv_profile"], profiles.attrs["wind_profile"])
    return Period(period, profiles, _night(index, night), step_h, sources)
