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
from opfbench.data.profiles import PAPER_DAY_TZ, PvSource
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


def _parse_time(text: str) -> pd.Timestamp:
    try:
        ts = pd.Timestamp(text)
    except (ValueError, TypeError) as exc:
        raise InputError(f"period: cannot read time {text!r} (use e.g. 2016-06-28T10:00)") from exc
    return ts.tz_localize(PAPER_DAY_TZ) if ts.tzinfo is None else ts.tz_convert(PAPER_DAY_TZ)


def _window(period: str, step_minutes: float | None) -> tuple[pd.DatetimeIndex, PvSource]:
    if period == "paper-day":
        return pd.date_range(PAPER_DAY, periods=1440, freq="1min", tz=PAPER_DAY_TZ), "bsrn"
    if period == "year":  # up to SimBench's last quarter hour (no extrapolation at finer steps)
        start = pd.Timestamp(f"{YEAR}-01-01", tz=PAPER_DAY_TZ)
        last = pd.Timestamp(f"{YEAR}-12-31 23:45", tz=PAPER_DAY_TZ)
        return pd.date_range(start, last, freq=pd.Timedelta(minutes=step_minutes or 15)), "simbench"
    first, sep, last = period.partition("..")
    if not sep:
        raise InputError(f"period must be 'paper-day', 'year' or 'START..END', got {period!r}")
    start, end = _parse_time(first), _parse_time(last)
    if end <= start:
        raise InputError(f"period {period!r}: END must come after START")
    bsrn = load_pv_minute().index
    inside = start >= bsrn[0] and end <= bsrn[-1] + pd.Timedelta(minutes=1)
    step = pd.Timedelta(minutes=step_minutes or (1 if inside else 15))
    index = pd.date_range(start, end, freq=step, inclusive="left")
    if len(index) < 1:
        raise InputError(f"period {period!r} holds no step of {step}")
    return index, "bsrn" if inside else "simbench"


def _night(index: pd.DatetimeIndex, night: str) -> np.ndarray:
    if night == "sun":
        return night_mask(index).to_numpy()
    start, _, end = night.partition("-")
    return night_mask_window(index, start, end).to_numpy()


def resolve_period(period: str, night: str, step_minutes: float | None = None) -> Period:
    """The period's steps, profiles and night mask (InputError for unknown periods or
    windows outside the data)."""
    if step_minutes is not None and not step_minutes > 0:
        raise InputError(f"step must be a positive number of minutes, got {step_minutes}")
    index, pv_source = _window(period, step_minutes)
    profiles = assemble_profiles(index, pv_source=pv_source)
    step_h = float((index[1] - index[0]) / pd.Timedelta(hours=1)) if len(index) > 1 else (step_minutes or 1) / 60
    sources = (profiles.attrs["load_profile"], profiles.attrs["pv_profile"], profiles.attrs["wind_profile"])
    return Period(period, profiles, _night(index, night), step_h, sources)
