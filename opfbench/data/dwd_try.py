"""DWD test reference years (TRY 2010, ``TRY2010_NN_Jahr.dat``): hourly weather of a
typical year.

The header names the columns (``RG IS MM DD HH N WR WG t p x RF ...``) above a ``***``
line; hours ``HH`` run 1..24 in MEZ, i.e. CET without daylight saving (UTC+1). A TRY
has no calendar year: it is placed in a stated non-leap year, hour ``HH`` of a day
stamped at ``HH:00`` (hour 24 = 00:00 of the next day). Wind direction 999 (no
direction) is treated as missing.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.data.textsource import Source, read_source
from opfbench.errors import DataError

#: The non-leap calendar year the typical year is placed in.
TRY_YEAR = 2010
#: Clock of the file (MEZ without daylight saving).
TRY_TZ = "Etc/GMT-1"
#: Output columns (file column, unit), in order.
TRY_COLUMNS = {
    "wind_speed_ms": ("WG", "m/s"),
    "wind_dir_deg": ("WR", "deg"),
    "temp_air_c": ("t", "degC"),
    "relative_humidity_pct": ("RF", "%"),
    "pressure_hpa": ("p", "hPa"),
}
_WIND_DIR_MISSING = 999.0


def parse_try(source: Source, year: int = TRY_YEAR) -> pd.DataFrame:
    """Parse a TRY 2010 file (path or text) into an hourly frame on a tz-aware
    (`TRY_TZ`) index in ``year``, with the columns of `TRY_COLUMNS` (m/s, degrees from
    north, °C, %, hPa at station height). Missing wind directions become NaN."""
    text, name = read_source(source)
    lines = text.splitlines()
    if not any("(MEZ)" in line for line in lines):
        raise DataError(f"{name}: header does not state hours in MEZ; not a TRY 2010 file?")
    try:
        head = next(i for i, line in enumerate(lines) if line.split()[:2] == ["RG", "IS"])
    except StopIteration:
        raise DataError(f"{name}: column header line 'RG IS MM DD HH ...' not found") from None
    names = lines[head].split()
    missing = [c for c in ("MM", "DD", "HH", *(f for f, _ in TRY_COLUMNS.values())) if c not in names]
    if missing:
        raise DataError(f"{name}: column(s) {missing} missing from the header")
    first = head + 2 if lines[head + 1].startswith("***") else head + 1
    rows = []
    for n, line in enumerate(lines[first:], start=first + 1):
        if not line.strip():
            continue
        tokens = line.split()
        if len(tokens) != len(names):
            raise DataError(f"{name}: line {n}: expected {len(names)} fields, got {len(tokens)}")
        try:
            rows.append([float(t) for t in tokens])
        except ValueError as exc:
            raise DataError(f"{name}: line {n}: {exc}") from exc
    table = pd.DataFrame(rows, columns=names)
    try:
        days = pd.to_datetime({"year": year, "month": table["MM"].astype(int), "day": table["DD"].astype(int)})
    except ValueError as exc:
        raise DataError(f"{name}: column 'time': invalid month/day ({exc})") from exc
    index = pd.DatetimeIndex(days + pd.to_timedelta(table["HH"].astype(int), unit="h")).tz_localize(TRY_TZ)
    out = pd.DataFrame({col: table[f].to_numpy() for col, (f, _) in TRY_COLUMNS.items()}, index=index)
    out["wind_dir_deg"] = out["wind_dir_deg"].replace(_WIND_DIR_MISSING, np.nan)
    return out
