"""Regenerate the embedded data files from the raw public sources.

    python -m opfbench.data.derive --source /path/to/shared/data [--out DIR]

``--source`` is the folder holding ``bsrn/``, ``try2010/`` and ``simbench/`` as described
in the project's data SOURCES.md; ``--out`` defaults to the package's ``files/``
folder. The output is byte-for-byte reproducible for the same raw files and library
versions (which the manifest records). Never run at import or load time.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from importlib.metadata import version
from pathlib import Path

import pandas as pd

from opfbench.data.bsrn import CLOSURE_MAX_ZENITH_DEG, WEATHER_UNITS, fill_bsrn_gaps, parse_bsrn_lr0100
from opfbench.data.cleaning import check_bounds, check_finite, check_time_index, fill_gaps_linear
from opfbench.data.dwd_try import TRY_COLUMNS, TRY_YEAR, parse_try
from opfbench.data.files_io import FILES_DIR, sha256, write_manifest, write_series_csv_gz
from opfbench.data.pv_plant import PV_PLANT, pv_ac_power_kw
from opfbench.data.simbench_profiles import GENERATION_PROFILES, LOAD_PROFILES, parse_simbench_profiles
from opfbench.data.sites import PAYERNE, POTSDAM
from opfbench.data.wind_plant import TURBINE, turbine_rating_kw, wind_power_kw
from opfbench.errors import OpfbenchError

BSRN_FILE = "bsrn/bsrn-pay0616.dat.gz"
TRY_FILE = "try2010/TRY2010_04_Jahr.dat"
SIMBENCH_RES_FILE = "simbench/RESProfile.csv.gz"
SIMBENCH_LOAD_FILE = "simbench/LoadProfile_subset.csv.gz"
SIMBENCH_LICENSE = "simbench/LICENSE"
LIBRARIES = ("numpy", "pandas", "pvlib", "windpowerlib")

_LINEAR = "linear interpolation in time; nearest value at the ends of the series"


def _entry(
    df: pd.DataFrame,
    file: str,
    source: Path,
    step: str,
    units: dict[str, str],
    gaps: dict[str, int],
    gap_method: str,
    bounds: dict[str, tuple[float, float]],
    **extra: object,
) -> dict:
    """Validated manifest entry of one dataset (the file's hash is added when written).
    ``bounds`` gives the physical range of the power columns."""
    check_time_index(df.index, file, pd.Timedelta(step))
    check_finite(df, file)
    check_bounds(df, file, bounds)
    return {
        "file": file,
        "source": f"{source.parent.name}/{source.name}",
        "source_sha256": sha256(source),
        "tz": str(df.index.tz),
        "step": step,
        "rows": len(df),
        "start": df.index[0].isoformat(),
        "end": df.index[-1].isoformat(),
        "columns": units,
        "gaps_filled": gaps,
        "gap_method": gap_method,
        "bounds": {col: list(b) for col, b in bounds.items()},
        **extra,
    }


def derive_pv_minute(source_dir: Path) -> tuple[pd.DataFrame, dict]:
    """BSRN Payerne June 2016 weather + AC power (kW) of `PV_PLANT`, 1 min, UTC."""
    src = source_dir / BSRN_FILE
    weather, gaps = fill_bsrn_gaps(parse_bsrn_lr0100(src), PAYERNE)
    df = weather.assign(pv_ac_kw=pv_ac_power_kw(weather, PAYERNE, PV_PLANT))
    units = {**WEATHER_UNITS, "pv_ac_kw": "kW"}
    entry = _entry(
        df,
        "pv_minute_payerne_2016-06.csv.gz",
        src,
        "1min",
        units,
        {**gaps, "pv_ac_kw": 0},
        f"{_LINEAR}; DNI gaps first rebuilt as (GHI - DHI)/cos(zenith) where the apparent zenith is "
        f"below {CLOSURE_MAX_ZENITH_DEG:g} deg",
        {"pv_ac_kw": (0.0, PV_PLANT.ac_rating_kw)},
        rating_kw=PV_PLANT.ac_rating_kw,
        model=(
            f"pvlib PVWatts: {PV_PLANT.dc_rating_kw} kW DC, {PV_PLANT.ac_rating_kw} kW AC, tilt "
            f"{PV_PLANT.tilt_deg} deg, azimuth {PV_PLANT.azimuth_deg} deg, Perez transposition, SAPM "
            f"open-rack cell temperature, {PV_PLANT.system_losses_pct} % losses, at {PAYERNE}"
        ),
    )
    return df, entry


def derive_wind_hourly(source_dir: Path) -> tuple[pd.DataFrame, dict]:
    """DWD TRY 2010 region 04 (Potsdam) weather + power (kW) of `TURBINE`, hourly, UTC+1."""
    src = source_dir / TRY_FILE
    weather, gaps = fill_gaps_linear(parse_try(src))
    df = weather.assign(wind_power_kw=wind_power_kw(weather, TURBINE))
    units = {col: unit for col, (_, unit) in TRY_COLUMNS.items()} | {"wind_power_kw": "kW"}
    rating = turbine_rating_kw(TURBINE)
    entry = _entry(
        df,
        "wind_hourly_potsdam_try2010.csv.gz",
        src,
        "1h",
        units,
        {**gaps, "wind_power_kw": 0},
        _LINEAR,
        {"wind_power_kw": (0.0, rating)},
        rating_kw=rating,
        year=TRY_YEAR,
        model=(
            f"windpowerlib: {TURBINE.turbine_type}, hub height {TURBINE.hub_height_m} m, logarithmic "
            f"profile from {TURBINE.wind_measurement_height_m} m with roughness length "
            f"{TURBINE.roughness_length_m} m, barometric density, density-corrected power curve, at {POTSDAM}"
        ),
    )
    return df, entry


def derive_simbench(source_dir: Path) -> tuple[pd.DataFrame, dict]:
    """Selected SimBench 2016 profiles, 15 min; generation profiles clipped to >= 0."""
    res, load = source_dir / SIMBENCH_RES_FILE, source_dir / SIMBENCH_LOAD_FILE
    raw = parse_simbench_profiles(res, GENERATION_PROFILES).join(parse_simbench_profiles(load, LOAD_PROFILES))
    df, gaps = fill_gaps_linear(raw)
    clipped = {col: int((df[col] < 0).sum()) for col in GENERATION_PROFILES}
    df[list(GENERATION_PROFILES)] = df[list(GENERATION_PROFILES)].clip(lower=0.0)
    profiles = {col: f"{SIMBENCH_RES_FILE}:{name}" for col, name in GENERATION_PROFILES.items()}
    profiles |= {col: f"{SIMBENCH_LOAD_FILE}:{name}" for col, name in LOAD_PROFILES.items()}
    entry = _entry(
        df,
        "simbench_profiles_2016.csv.gz",
        res,
        "15min",
        dict.fromkeys(df.columns, "p.u."),
        gaps,
        _LINEAR,
        dict.fromkeys(GENERATION_PROFILES, (0.0, 1.0)),
        profiles=profiles,
        load_source_sha256=sha256(load),
        negatives_clipped=clipped,
    )
    return df, entry


#: dataset name -> (derivation, decimals per column)
DERIVED = {
    "pv_minute": (
        derive_pv_minute,
        {"ghi_wm2": 1, "dni_wm2": 1, "dhi_wm2": 1, "temp_air_c": 2, "relative_humidity_pct": 2, "pressure_hpa": 2, "pv_ac_kw": 4},
    ),
    "wind_hourly": (
        derive_wind_hourly,
        {
            "wind_speed_ms": 2,
            "wind_dir_deg": 1,
            "temp_air_c": 2,
            "relative_humidity_pct": 2,
            "pressure_hpa": 2,
            "wind_power_kw": 3,
        },
    ),
    "simbench_profiles": (derive_simbench, dict.fromkeys((*GENERATION_PROFILES, *LOAD_PROFILES), 4)),
}


def derive_all(source_dir: Path, out_dir: Path = FILES_DIR) -> dict:
    """Derive every dataset from ``source_dir`` into ``out_dir``; return the manifest."""
    source_dir, out_dir = Path(source_dir), Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    datasets = {}
    for name, (derive, decimals) in DERIVED.items():
        df, entry = derive(source_dir)
        write_series_csv_gz(df, out_dir / entry["file"], decimals)
        datasets[name] = {**entry, "sha256": sha256(out_dir / entry["file"])}
    shutil.copyfile(source_dir / SIMBENCH_LICENSE, out_dir / "SIMBENCH_LICENSE.txt")
    manifest = {
        "generated_by": "python -m opfbench.data.derive",
        "libraries": {lib: version(lib) for lib in LIBRARIES},
        "datasets": datasets,
    }
    write_manifest(manifest, out_dir)
    return manifest


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.data.derive", description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, required=True, help="folder with bsrn/, try2010/, simbench/")
    parser.add_argument("--out", type=Path, default=FILES_DIR, help="output folder (default: package files/)")
    args = parser.parse_args(argv)
    try:
        manifest = derive_all(args.source, args.out)
    except OpfbenchError as exc:
        print(f"derive: error: {exc}", file=sys.stderr)
        return 2
    for name, entry in manifest["datasets"].items():
        size = (args.out / entry["file"]).stat().st_size
        print(f"{name}: {entry['rows']} rows, {size / 1e6:.2f} MB, gaps filled {entry['gaps_filled']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
