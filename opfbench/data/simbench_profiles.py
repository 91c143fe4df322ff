"""SimBench profile tables (``RESProfile.csv``, ``LoadProfile.csv``): 15-min normalised
profiles of the year 2016.

The files are ``;``-separated with a ``time`` column ``dd.mm.yyyy HH:MM`` on the German
local clock *with* daylight saving: 27 March jumps from 01:45 to 03:00 and 30 October
repeats 02:00–02:45. Timestamps are therefore localised to Europe/Berlin (the repeated
hour resolved by order), giving a strictly increasing 15-min index of 35 136 rows
(`opfbench.io.simbench.simbench_time_index`, which reads the grids' own profiles too).
"""

from __future__ import annotations

import io

import pandas as pd

from opfbench.data.textsource import Source, read_source
from opfbench.errors import DataError
from opfbench.io.simbench import simbench_time_index

#: Kept generation profiles: output column -> SimBench column (p.u. of installed power).
GENERATION_PROFILES = {"pv_pu": "PV3", "wind_pu": "WP4"}
#: Kept load profiles: output column -> SimBench column (p.u., SimBench's normalisation).
LOAD_PROFILES = {
    "h0a_p_pu": "H0-A_pload",
    "h0a_q_pu": "H0-A_qload",
    "g0a_p_pu": "G0-A_pload",
    "g0a_q_pu": "G0-A_qload",
    "mv_semiurb_p_pu": "mv_semiurb_pload",
    "mv_semiurb_q_pu": "mv_semiurb_qload",
}


def parse_simbench_profiles(source: Source, columns: dict[str, str]) -> pd.DataFrame:
    """Read the SimBench ``columns`` (output name -> file column) of a profile table
    (path, ``.gz`` path or text) onto a tz-aware (Europe/Berlin) 15-min index.
    Values are returned as published (NaN where a cell is empty)."""
    text, name = read_source(source)
    try:
        table = pd.read_csv(io.StringIO(text), sep=";")
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise DataError(f"{name}: not a ';'-separated SimBench table ({exc})") from exc
    missing = [c for c in ("time", *columns.values()) if c not in table.columns]
    if missing:
        raise DataError(f"{name}: column(s) {missing} missing")
    index = simbench_time_index(table["time"], name)
    out = pd.DataFrame(index=index)
    for col, src in columns.items():
        values = pd.to_numeric(table[src], errors="coerce")
        if values.isna().sum() > table[src].isna().sum():
            raise DataError(f"{name}: column {src!r} holds non-numeric values")
        out[col] = values.to_numpy()
    return out
