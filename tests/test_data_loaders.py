"""Loaders of the embedded derived files: spans, units, physical ranges, gap counts,
size, and DataError on broken files."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from opfbench.data import load_pv_minute, load_simbench_profiles, load_wind_hourly, night_mask
from opfbench.data.files_io import FILES_DIR, sha256, write_manifest, write_series_csv_gz
from opfbench.data.loaders import load_dataset
from opfbench.data.sites import PAYERNE
from opfbench.data.wind_plant import turbine_rating_kw
from opfbench.errors import DataError

MANIFEST = json.loads((FILES_DIR / "manifest.json").read_text())["datasets"]


def assert_regular(df: pd.DataFrame, start: str, rows: int, step: str) -> None:
    assert isinstance(df.index, pd.DatetimeIndex) and df.index.tz is not None
    assert len(df) == rows
    assert df.index[0] == pd.Timestamp(start)
    assert (np.diff(df.index.asi8) == pd.Timedelta(step).value).all()


def assert_gaps_match_manifest(df: pd.DataFrame, name: str, max_fraction: float) -> None:
    gaps = df.attrs["gaps_filled"]
    assert gaps == MANIFEST[name]["gaps_filled"]
    assert set(gaps) == set(df.columns)
    assert max(gaps.values()) / len(df) <= max_fraction


def test_pv_minute_span_units_and_physics():
    df = load_pv_minute()
    assert_regular(df, "2016-06-01 00:00+00:00", 30 * 1440, "1min")
    assert str(df.index.tz) == "UTC"
    assert df.columns.tolist() == [
        "ghi_wm2",
        "dni_wm2",
        "dhi_wm2",
        "temp_air_c",
        "relative_humidity_pct",
        "pressure_hpa",
        "pv_ac_kw",
    ]
    assert df.attrs["rating_kw"] == 10.0
    assert df.attrs["units"]["pv_ac_kw"] == "kW" and df.attrs["units"]["ghi_wm2"] == "W/m2"
    pv = df["pv_ac_kw"]
    assert pv.between(0.0, df.attrs["rating_kw"]).all()
    night = night_mask(df.index, PAYERNE.latitude, PAYERNE.longitude)
    assert 0.3 < night.mean() < 0.4  # June at 46.8 N: about 8.5 h of night
    assert (pv[night] == 0).all()
    assert (pv[~night] > 0).mean() > 0.9
    assert df["ghi_wm2"].between(-10, 1450).all()  # measured max 1404 W/m2 (cloud enhancement)
    assert df["dni_wm2"].between(0, 1100).all() and df["dhi_wm2"].between(-10, 800).all()
    assert df["temp_air_c"].between(-10, 45).all() and df["relative_humidity_pct"].between(0, 101).all()
    assert df["pressure_hpa"].between(900, 1000).all()  # station at 491 m
    assert np.corrcoef(pv, df["ghi_wm2"])[0, 1] > 0.9
    assert_gaps_match_manifest(df, "pv_minute", max_fraction=0.05)


def test_wind_hourly_span_units_and_physics():
    df = load_wind_hourly()
    assert_regular(df, "2010-01-01 01:00+01:00", 8760, "1h")
    assert df.index.tz.utcoffset(None) == pd.Timedelta("1h")
    assert df.columns.tolist() == [
        "wind_speed_ms",
        "wind_dir_deg",
        "temp_air_c",
        "relative_humidity_pct",
        "pressure_hpa",
        "wind_power_kw",
    ]
    assert df.attrs["rating_kw"] == turbine_rating_kw() == 2350.0
    power = df["wind_power_kw"]
    assert power.between(0.0, df.attrs["rating_kw"]).all()
    assert df["wind_speed_ms"].between(0, 40).all() and df["wind_dir_deg"].between(0, 360).all()
    assert power.corr(df["wind_speed_ms"], method="spearman") > 0.9
    assert (power[df["wind_speed_ms"] == 0] == 0).all()
    assert_gaps_match_manifest(df, "wind_hourly", max_fraction=0.01)


def test_simbench_profiles_span_and_ranges():
    df = load_simbench_profiles()
    assert_regular(df, "2016-01-01 00:00+01:00", 35136, "15min")
    assert df.index[-1] == pd.Timestamp("2016-12-31 23:45+01:00")
    assert df.columns.tolist() == [
        "pv_pu",
        "wind_pu",
        "h0a_p_pu",
        "h0a_q_pu",
        "g0a_p_pu",
        "g0a_q_pu",
        "mv_semiurb_p_pu",
        "mv_semiurb_q_pu",
    ]
    assert df[["pv_pu", "wind_pu"]].stack().between(0, 1).all()
    assert df["h0a_p_pu"].max() == 1.0 and df["g0a_p_pu"].max() == 1.0
    assert df.attrs["profiles"]["pv_pu"].endswith(":PV3") and df.attrs["profiles"]["wind_pu"].endswith(":WP4")
    assert_gaps_match_manifest(df, "simbench_profiles", max_fraction=0.01)


def test_loaders_return_independent_copies():
    a = load_pv_minute()
    a.iloc[0, 0] = -1e9
    a.attrs["rating_kw"] = -1
    b = load_pv_minute()
    assert b.iloc[0, 0] != -1e9 and b.attrs["rating_kw"] == 10.0


def test_derived_files_are_small():
    total = sum(p.stat().st_size for p in FILES_DIR.iterdir() if p.is_file())
    assert total <= 8e6


def write_dataset(folder, df: pd.DataFrame, **overrides) -> None:
    folder.mkdir()
    write_series_csv_gz(df, folder / "x.csv.gz", dict.fromkeys(df.columns, 3))
    entry = {
        "file": "x.csv.gz",
        "source": "fake",
        "tz": "UTC",
        "step": "1min",
        "columns": dict.fromkeys(df.columns, "kW"),
        "gaps_filled": dict.fromkeys(df.columns, 0),
        "gap_method": "linear",
        "bounds": {"p_kw": [0, 10]},
        "rating_kw": 10.0,
        "model": "fake",
        "sha256": sha256(folder / "x.csv.gz"),
    }
    write_manifest({"datasets": {"x": entry | overrides}}, folder)


def fake(values, times=None) -> pd.DataFrame:
    index = (
        pd.DatetimeIndex(times, tz="UTC") if times else pd.date_range("2016-06-01", periods=len(values), freq="1min", tz="UTC")
    )
    return pd.DataFrame({"p_kw": values}, index=index)


def test_load_dataset_reads_a_valid_small_file(tmp_path):
    write_dataset(tmp_path / "ok", fake([0.0, 1.5, 2.25]))
    df = load_dataset("x", tmp_path / "ok")
    assert df["p_kw"].tolist() == [0.0, 1.5, 2.25] and df.attrs["rating_kw"] == 10.0


@pytest.mark.parametrize(
    "df, overrides, message",
    [
        (fake([0.0, np.nan, 1.0]), {}, r"x\.csv\.gz: column 'p_kw' has 1 NaN/inf"),
        (fake([0.0, np.inf, 1.0]), {}, r"x\.csv\.gz: column 'p_kw' has 1 NaN/inf"),
        (
            fake([0.0, 1.0, 2.0], ["2016-06-01 00:00", "2016-06-01 00:02", "2016-06-01 00:01"]),
            {},
            r"x\.csv\.gz: column 'time' is not strictly increasing",
        ),
        (
            fake([0.0, 1.0, 2.0], ["2016-06-01 00:00", "2016-06-01 00:01", "2016-06-01 00:03"]),
            {},
            r"x\.csv\.gz: column 'time' is not evenly spaced",
        ),
        (fake([0.0, 1.0, 2.0]), {"rating_kw": -10.0}, r"x\.csv\.gz: rating_kw must be a positive"),
        (fake([0.0, -1.0, 2.0]), {}, r"x\.csv\.gz: column 'p_kw' leaves \[0, 10\]"),
        (fake([0.0, 1.0, 2.0]), {"sha256": "0" * 64}, "changed since derivation"),
        (fake([0.0, 1.0, 2.0]), {"columns": {"q_kw": "kW"}}, "differ from the manifest"),
    ],
)
def test_load_dataset_rejects_broken_files(tmp_path, df, overrides, message):
    write_dataset(tmp_path / "broken", df, **overrides)
    with pytest.raises(DataError, match=message):
        load_dataset("x", tmp_path / "broken")
