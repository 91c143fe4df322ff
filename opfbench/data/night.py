"""Night hours: from the sun's position at a site, or an explicit clock window."""

from __future__ import annotations

import datetime as dt

import pandas as pd

from opfbench.data.sites import PAYERNE
from opfbench.errors import InputError


def _require_aware(index: pd.DatetimeIndex) -> None:
    if not isinstance(index, pd.DatetimeIndex) or index.tz is None:
        raise InputError("night mask needs a time-zone-aware DatetimeIndex")


def night_mask(
    index: pd.DatetimeIndex,
    latitude: float = PAYERNE.latitude,
    longitude: float = PAYERNE.longitude,
    altitude_m: float = PAYERNE.altitude_m,
) -> pd.Series:
    """True where the sun is below the horizon (sunset → sunrise) at the site
    (degrees north/east, m): apparent, refraction-corrected elevation of the sun's
    centre < 0° (pvlib NREL SPA). Returns a boolean Series on ``index``."""
    from pvlib.solarposition import get_solarposition

    _require_aware(index)
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 180.0):
        raise InputError(f"latitude/longitude out of range: {latitude}, {longitude}")
    elevation = get_solarposition(index, latitude, longitude, altitude_m)["apparent_elevation"]
    return pd.Series(elevation.to_numpy() < 0.0, index=index, name="night")


def night_mask_window(index: pd.DatetimeIndex, start: str = "20:00", end: str = "05:00") -> pd.Series:
    """True for local clock times (the index's own time zone) in [start, end); the
    window may wrap midnight (paper: 20:00–05:00). Returns a boolean Series."""
    _require_aware(index)
    try:
        t0, t1 = dt.time.fromisoformat(start), dt.time.fromisoformat(end)
    except ValueError as exc:
        raise InputError(f"night window times must be HH:MM, got {start!r}, {end!r}") from exc
    if t0 == t1:
        raise InputError(f"night window {start}–{end} is empty")
    minutes = index.hour * 60 + index.minute + index.second / 60
    m0, m1 = (t.hour * 60 + t.minute + t.second / 60 for t in (t0, t1))
    inside = (minutes >= m0) & (minutes < m1) if m0 < m1 else (minutes >= m0) | (minutes < m1)
    return pd.Series(inside, index=index, name="night")
