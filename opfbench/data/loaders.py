"""Loaders of the embedded derived series (read from ``opfbench/data/files``; never
from the raw sources, never from the network).

Each loader validates what it reads — file hash against the manifest, a tz-aware
strictly increasing evenly spaced index, finite values, a positive rating, power
within [0, rating] — and
raises `opfbench.errors.DataError` naming the file and the column otherwise.
``df.attrs`` carries ``units`` (column → unit), ``gaps_filled`` (column → number of
points filled when the file was derived) and, for plant outputs, ``rating_kw``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import pandas as pd

from opfbench.data.cleaning import check_bounds, check_finite, check_rating, check_time_index
from opfbench.data.files_io import FILES_DIR, read_manifest, read_series_csv_gz, sha256
from opfbench.errors import DataError


@lru_cache(maxsize=8)
def _load(name: str, folder: Path) -> pd.DataFrame:
    entry = read_manifest(folder)["datasets"].get(name)
    if entry is None:
        raise DataError(f"{folder / 'manifest.json'}: no dataset {name!r}")
    path = folder / entry["file"]
    if not path.exists() or sha256(path) != entry["sha256"]:
        raise DataError(
            f"{path}: missing or changed since derivation (hash differs from the manifest); rerun python -m opfbench.data.derive"
        )
    df = read_series_csv_gz(path, entry["tz"])
    if list(df.columns) != list(entry["columns"]):
        raise DataError(f"{path}: columns {list(df.columns)} differ from the manifest's {list(entry['columns'])}")
    check_time_index(df.index, str(path), pd.Timedelta(entry["step"]))
    check_finite(df, str(path))
    df.attrs = {
        "name": name,
        "source": entry["source"],
        "units": dict(entry["columns"]),
        "gaps_filled": dict(entry["gaps_filled"]),
        "gap_method": entry["gap_method"],
    }
    if "rating_kw" in entry:
        df.attrs["rating_kw"] = check_rating(entry["rating_kw"], str(path), "rating_kw")
        df.attrs["model"] = entry["model"]
    if "profiles" in entry:
        df.attrs["profiles"] = dict(entry["profiles"])
    check_bounds(df, str(path), {col: (low, high) for col, (low, high) in entry["bounds"].items()})
    return df


def load_dataset(name: str, files_dir: Path | None = None) -> pd.DataFrame:
    """A fresh copy of derived dataset ``name`` (a key of the manifest's ``datasets``)."""
    return _load(name, Path(files_dir or FILES_DIR).resolve()).copy(deep=True)


def load_pv_minute(files_dir: Path | None = None) -> pd.DataFrame:
    """BSRN Payerne, June 2016, 1 min, UTC index (43 200 rows).

    Columns: ``ghi_wm2, dni_wm2, dhi_wm2`` (W/m²), ``temp_air_c`` (°C),
    ``relative_humidity_pct`` (%), ``pressure_hpa`` (hPa, station level) and
    ``pv_ac_kw`` (kW AC of the 10 kW plant of `opfbench.data.pv_plant`);
    ``attrs["rating_kw"] = 10.0``. Irradiance is as measured (a few W/m² below zero
    at night = pyranometer thermal offset); humidity reaches 100.5 % (sensor)."""
    return load_dataset("pv_minute", files_dir)


def load_wind_hourly(files_dir: Path | None = None) -> pd.DataFrame:
    """DWD TRY 2010 region 04 (Potsdam) placed in 2010, hourly on UTC+1 (8760 rows).

    Columns: ``wind_speed_ms`` (m/s at 10 m), ``wind_dir_deg`` (degrees from north),
    ``temp_air_c`` (°C at 2 m), ``relative_humidity_pct`` (%), ``pressure_hpa`` (hPa,
    station level), ``wind_power_kw`` (kW of the Enercon E-82/2350 of
    `opfbench.data.wind_plant`); ``attrs["rating_kw"] = 2350.0``."""
    return load_dataset("wind_hourly", files_dir)


def load_simbench_profiles(files_dir: Path | None = None) -> pd.DataFrame:
    """SimBench 2016 profiles, 15 min, Europe/Berlin index (35 136 rows), all p.u.:
    ``pv_pu`` (PV3, of installed power), ``wind_pu`` (WP4, of installed power),
    ``h0a_p_pu, h0a_q_pu`` (household H0-A), ``g0a_p_pu, g0a_q_pu`` (commercial G0-A),
    ``mv_semiurb_p_pu, mv_semiurb_q_pu`` (aggregated semi-urban MV load); load P and
    Q in SimBench's normalisation. ``attrs["profiles"]`` names each source column."""
    return load_dataset("simbench_profiles", files_dir)


def _step_label(step: pd.Timedelta) -> str:
    minutes = int(step.total_seconds() // 60)
    return f"{minutes // 60}h" if minutes % 60 == 0 else f"{minutes}min"


def describe_datasets(files_dir: Path | None = None) -> list[dict]:
    """One summary per embedded dataset, measured on the loaded data: ``name, rows,
    start, end`` (ISO 8601 with offset), ``step`` (e.g. ``"15min"``, ``"1h"``),
    ``columns`` (column → unit) and ``gaps_filled`` (column → points filled)."""
    folder = Path(files_dir or FILES_DIR).resolve()
    summaries = []
    for name in read_manifest(folder)["datasets"]:
        df = load_dataset(name, folder)
        summaries.append(
            {
                "name": name,
                "rows": len(df),
                "start": df.index[0].isoformat(),
                "end": df.index[-1].isoformat(),
                "step": _step_label(df.index[1] - df.index[0]),
                "columns": df.attrs["units"],
                "gaps_filled": df.attrs["gaps_filled"],
            }
        )
    return summaries
