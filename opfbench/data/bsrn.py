"""BSRN station-to-archive files: the basic minute record LR0100.

A BSRN monthly file holds logical records, each starting with a line ``*U0100`` or
``*C0100`` (``U``/``C`` = unchanged/changed) and ending at the next ``*`` line. LR0001
gives station, month and year (``  21  6 2016  1``). LR0100 has two text lines per
minute, times in UTC:

* line 1: day, minute of day (0..1439), then avg/std/min/max of global (GHI) and
  direct normal (DNI) irradiance;
* line 2: avg/std/min/max of diffuse (DHI) and long-wave downward irradiance, then
  air temperature, relative humidity and station pressure.

Irradiance in W/m², temperature in °C, humidity in %, pressure in hPa. Missing values
are ``-999`` (irradiance, pressure) and ``-99.9`` (temperature, humidity).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.data.sites import Site
from opfbench.data.textsource import Source, read_source
from opfbench.errors import DataError

#: Output columns with their units.
WEATHER_UNITS = {
    "ghi_wm2": "W/m2",
    "dni_wm2": "W/m2",
    "dhi_wm2": "W/m2",
    "temp_air_c": "degC",
    "relative_humidity_pct": "%",
    "pressure_hpa": "hPa",
}
# column -> (line of the minute record, token position, missing-value sentinel)
_LAYOUT = {
    "ghi_wm2": (0, 2, -999.0),
    "dni_wm2": (0, 6, -999.0),
    "dhi_wm2": (1, 0, -999.0),
    "temp_air_c": (1, 8, -99.9),
    "relative_humidity_pct": (1, 9, -99.9),
    "pressure_hpa": (1, 10, -999.0),
}
_TOKENS_PER_LINE = (10, 11)
#: DNI gaps are rebuilt from GHI and DHI only while the sun is higher than this (degrees).
CLOSURE_MAX_ZENITH_DEG = 85.0


def _records(lines: list[str], code: str) -> tuple[int, list[str]]:
    """Return (index of the first body line, body lines) of logical record ``code``."""
    for i, line in enumerate(lines):
        if line.startswith(("*U" + code, "*C" + code)):
            end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("*")), len(lines))
            return i + 1, lines[i + 1 : end]
    raise DataError(f"logical record {code} not found")


def parse_bsrn_lr0100(source: Source) -> pd.DataFrame:
    """Parse LR0100 of a BSRN file (path, ``.gz`` path or text) into a 1-min frame.

    Index: UTC minutes of the file's month, every minute present. Columns as in
    `WEATHER_UNITS`; missing values become NaN (not filled here)."""
    text, name = read_source(source)
    lines = text.splitlines()
    try:
        _, head = _records(lines, "0001")
        _station, month, year = (int(t) for t in head[0].split()[:3])
        first, body = _records(lines, "0100")
    except (DataError, ValueError, IndexError) as exc:
        raise DataError(f"{name}: not a BSRN station-to-archive file ({exc})") from exc
    if len(body) % 2:
        raise DataError(f"{name}: LR0100 has an odd number of lines ({len(body)})")
    n = len(body) // 2
    values = np.empty((n, len(_LAYOUT)))
    minutes = np.empty(n, dtype=np.int64)
    for k in range(n):
        pair = (body[2 * k].split(), body[2 * k + 1].split())
        for line, (tokens, want) in enumerate(zip(pair, _TOKENS_PER_LINE, strict=True)):
            if len(tokens) != want:
                raise DataError(f"{name}: line {first + 2 * k + line + 1}: expected {want} fields, got {len(tokens)}")
        try:
            day, minute = int(pair[0][0]), int(pair[0][1])
            values[k] = [float(pair[ln][pos]) for ln, pos, _ in _LAYOUT.values()]
        except ValueError as exc:
            raise DataError(f"{name}: line {first + 2 * k + 1}: {exc}") from exc
        minutes[k] = (day - 1) * 1440 + minute
    start = pd.Timestamp(year=year, month=month, day=1, tz="UTC")
    index = pd.DatetimeIndex(start + pd.to_timedelta(minutes, unit="min"))
    steps = np.diff(minutes)
    if (steps != 1).any():
        pos = int((steps != 1).argmax()) + 1
        raise DataError(f"{name}: column 'time' is not consecutive minutes at {index[pos]}")
    sentinels = np.array([s for _, _, s in _LAYOUT.values()])
    values[np.isclose(values, sentinels)] = np.nan
    return pd.DataFrame(values, index=index, columns=list(_LAYOUT))


def fill_bsrn_gaps(raw: pd.DataFrame, site: Site) -> tuple[pd.DataFrame, dict[str, int]]:
    """Fill the gaps of a `parse_bsrn_lr0100` frame measured at ``site``.

    GHI, DHI, temperature, humidity and pressure: linear interpolation in time
    (`fill_gaps_linear`). DNI, whose sun tracker fails for hours at a time, is rebuilt
    first from the closure DNI = (GHI − DHI)/cos(zenith) wherever the apparent solar
    zenith is below `CLOSURE_MAX_ZENITH_DEG`, clipped to [0, extraterrestrial DNI];
    the remaining DNI gaps (sun low or down) are interpolated linearly.
    Returns the filled frame and the number of filled points per column."""
    from pvlib.irradiance import get_extra_radiation
    from pvlib.solarposition import get_solarposition

    from opfbench.data.cleaning import fill_gaps_linear

    others = [c for c in raw.columns if c != "dni_wm2"]
    filled, counts = fill_gaps_linear(raw[others])
    zenith = get_solarposition(raw.index, site.latitude, site.longitude, site.altitude_m)["apparent_zenith"]
    closure = (filled["ghi_wm2"] - filled["dhi_wm2"]) / np.cos(np.radians(zenith))
    closure = closure.clip(lower=0.0, upper=get_extra_radiation(raw.index))
    dni = raw["dni_wm2"].where(raw["dni_wm2"].notna() | (zenith >= CLOSURE_MAX_ZENITH_DEG), closure)
    filled_dni, _ = fill_gaps_linear(dni.to_frame())
    counts["dni_wm2"] = int(raw["dni_wm2"].isna().sum())
    columns = list(raw.columns)
    return filled.assign(dni_wm2=filled_dni["dni_wm2"])[columns], {c: counts[c] for c in columns}
