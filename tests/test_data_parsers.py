"""Raw-file parsers and cleaning on small inputs written here (no raw data needed)."""

from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pytest

from opfbench.data.bsrn import fill_bsrn_gaps, parse_bsrn_lr0100
from opfbench.data.cleaning import check_bounds, check_finite, check_rating, check_time_index, fill_gaps_linear
from opfbench.data.dwd_try import parse_try
from opfbench.data.simbench_profiles import parse_simbench_profiles
from opfbench.data.sites import PAYERNE
from opfbench.errors import DataError

BSRN_HEAD = "*U0001\n 21  6 2016  1\n*U0100\n"
#          day min  ghi avg std min max  dni avg std min max
LINE1 = "{d:3d} {m:4d} {ghi:6d}   0.1  0  0 {dni:6d}   0.0    0    0"
#                  dhi avg std min max  lwd avg std min max   temp  rh   p
LINE2 = "           {dhi:6d}   0.2   -1    0    348   0.3  347  349   {t:6.1f} {rh:5.1f} {p:4d}"


def bsrn_text(rows: list[tuple]) -> str:
    body = "".join(
        LINE1.format(d=d, m=m, ghi=g, dni=n) + "\n" + LINE2.format(dhi=h, t=t, rh=r, p=p) + "\n"
        for d, m, g, n, h, t, r, p in rows
    )
    return BSRN_HEAD + body + "*U0300\n  1    0 whatever\n"


def test_bsrn_parse_maps_fields_and_missing_values():
    text = bsrn_text(
        [
            (1, 0, 10, 20, 5, 9.3, 95.0, 958),
            (1, 1, -999, -999, 6, -99.9, -99.9, -999),
            (1, 2, 30, 40, 7, 9.7, 97.0, 960),
        ]
    )
    df = parse_bsrn_lr0100(text)
    assert list(df.index) == list(pd.date_range("2016-06-01", periods=3, freq="1min", tz="UTC"))
    assert df.loc[df.index[0]].tolist() == [10, 20, 5, 9.3, 95.0, 958]
    assert df.iloc[1].isna().tolist() == [True, True, False, True, True, True]
    filled, counts = fill_gaps_linear(df)
    assert counts == {"ghi_wm2": 1, "dni_wm2": 1, "dhi_wm2": 0, "temp_air_c": 1, "relative_humidity_pct": 1, "pressure_hpa": 1}
    assert filled.iloc[1].tolist() == pytest.approx([20, 30, 6, 9.5, 96.0, 959])


def test_bsrn_parse_reads_gzipped_path_and_day_offset(tmp_path):
    path = tmp_path / "x.dat.gz"
    path.write_bytes(gzip.compress(bsrn_text([(2, 1439, 0, 0, 0, 1.0, 50.0, 950)]).encode()))
    df = parse_bsrn_lr0100(path)
    assert df.index[0] == pd.Timestamp("2016-06-02 23:59", tz="UTC")


def test_bsrn_dni_gap_rebuilt_from_closure_at_noon_and_linear_at_night():
    noon = (pd.Timestamp("2016-06-21 11:30", tz="UTC") - pd.Timestamp("2016-06-21", tz="UTC")).seconds // 60
    text = bsrn_text(
        [
            (21, noon - 1, 900, 800, 100, 20.0, 50.0, 960),
            (21, noon, 900, -999, 100, 20.0, 50.0, 960),
            (21, noon + 1, 900, 800, 100, 20.0, 50.0, 960),
        ]
    )
    filled, counts = fill_bsrn_gaps(parse_bsrn_lr0100(text), PAYERNE)
    from pvlib.solarposition import get_solarposition

    zenith = get_solarposition(filled.index[1:2], PAYERNE.latitude, PAYERNE.longitude, PAYERNE.altitude_m)
    expected = 800 / np.cos(np.radians(zenith["apparent_zenith"].iloc[0]))
    assert filled["dni_wm2"].iloc[1] == pytest.approx(expected)
    assert counts["dni_wm2"] == 1
    night = bsrn_text(
        [(21, 0, 0, 2, 0, 10.0, 90.0, 960), (21, 1, 0, -999, 0, 10.0, 90.0, 960), (21, 2, 0, 4, 0, 10.0, 90.0, 960)]
    )
    assert fill_bsrn_gaps(parse_bsrn_lr0100(night), PAYERNE)[0]["dni_wm2"].iloc[1] == 3


@pytest.mark.parametrize(
    "rows, message",
    [
        ([(1, 0, 0, 0, 0, 1.0, 1.0, 950), (1, 2, 0, 0, 0, 1.0, 1.0, 950)], "'time'"),
        ([(1, 1, 0, 0, 0, 1.0, 1.0, 950), (1, 0, 0, 0, 0, 1.0, 1.0, 950)], "'time'"),
    ],
)
def test_bsrn_rejects_non_consecutive_time(rows, message):
    with pytest.raises(DataError, match=message):
        parse_bsrn_lr0100(bsrn_text(rows))


def test_bsrn_rejects_malformed_records(tmp_path):
    good = bsrn_text([(1, 0, 0, 0, 0, 1.0, 1.0, 950)])
    bad_fields = good.replace(" 950\n", "\n")
    path = tmp_path / "bad.dat"
    path.write_text(bad_fields)
    with pytest.raises(DataError, match=r"bad\.dat: line 5: expected 11 fields"):
        parse_bsrn_lr0100(path)
    with pytest.raises(DataError, match="odd number"):
        parse_bsrn_lr0100(good.replace("*U0300", "extra\n*U0300"))
    with pytest.raises(DataError, match="not a BSRN"):
        parse_bsrn_lr0100("just\ntext\n")


TRY_HEAD = """TRY04   Nordostdeutsches Tiefland
HH Stunde (MEZ)                                                         {1..24}

RG    IS  MM  DD  HH  N   WR      WG       t       p        x   RF   W     B     D IK    A      E IL
***
"""
TRY_ROW = " 4     1  {mm:2d}  {dd:2d}  {hh:2d}  7  {wr:3d}     {wg:3.1f}    -2.6   1005.3     2.2   93  70     0     0 1   251   -285  9\n"


def test_try_parse_places_typical_year_on_cet_clock():
    text = TRY_HEAD + "".join(
        TRY_ROW.format(mm=1, dd=1, hh=h, wr=wr, wg=wg) for h, wr, wg in [(1, 230, 5.7), (2, 999, 6.0), (24, 250, 3.0)]
    )
    df = parse_try(text)
    assert str(df.index.tz) == "Etc/GMT-1"
    assert list(df.index.tz_convert("UTC")) == [
        pd.Timestamp(t, tz="UTC") for t in ("2010-01-01 00:00", "2010-01-01 01:00", "2010-01-01 23:00")
    ]
    assert df.columns.tolist() == ["wind_speed_ms", "wind_dir_deg", "temp_air_c", "relative_humidity_pct", "pressure_hpa"]
    assert df["wind_speed_ms"].tolist() == [5.7, 6.0, 3.0]
    assert np.isnan(df["wind_dir_deg"].iloc[1])
    assert df.iloc[0, 2:].tolist() == [-2.6, 93, 1005.3]


def test_try_rejects_bad_inputs():
    row = TRY_ROW.format(mm=1, dd=1, hh=1, wr=230, wg=5.7)
    with pytest.raises(DataError, match="MEZ"):
        parse_try(TRY_HEAD.replace("(MEZ)", "(UTC)") + row)
    with pytest.raises(DataError, match=r"\['RF'\]"):
        parse_try(TRY_HEAD.replace(" RF ", " XX ") + row)
    with pytest.raises(DataError, match="line 6: expected 19 fields"):
        parse_try(TRY_HEAD + row.replace(" 9\n", "\n"))
    with pytest.raises(DataError, match="'time'"):
        parse_try(TRY_HEAD + TRY_ROW.format(mm=2, dd=30, hh=1, wr=230, wg=5.7))


SIMBENCH_DST = """time;PV3;WP4;other
27.03.2016 01:30;0.0;0.5;1
27.03.2016 01:45;0.0;0.6;1
27.03.2016 03:00;0.0;0.7;1
27.03.2016 03:15;0.1;0.8;1
"""


def test_simbench_parse_localises_daylight_saving_jumps():
    df = parse_simbench_profiles(SIMBENCH_DST, {"pv_pu": "PV3", "wind_pu": "WP4"})
    assert list(df.index.tz_convert("UTC")) == list(pd.date_range("2016-03-27 00:30", periods=4, freq="15min", tz="UTC"))
    assert df["wind_pu"].tolist() == [0.5, 0.6, 0.7, 0.8]
    repeated = "time;WP4\n" + "".join(
        f"30.10.2016 {t};{v}\n" for v, t in enumerate(["02:30", "02:45", "02:00", "02:15", "02:30", "02:45", "03:00"])
    )
    fall = parse_simbench_profiles(repeated, {"wind_pu": "WP4"})
    assert list(fall.index.tz_convert("UTC")) == list(pd.date_range("2016-10-30 00:30", periods=7, freq="15min", tz="UTC"))


def test_simbench_rejects_bad_time_and_columns():
    swapped = SIMBENCH_DST.replace("01:30", "XX").replace("01:45", "01:30").replace("XX", "01:45")
    with pytest.raises(DataError, match="<text>: column 'time'"):
        parse_simbench_profiles(swapped, {"wind_pu": "WP4"})
    with pytest.raises(DataError, match=r"\['WP9'\] missing"):
        parse_simbench_profiles(SIMBENCH_DST, {"wind_pu": "WP9"})
    with pytest.raises(DataError, match="'WP4' holds non-numeric"):
        parse_simbench_profiles(SIMBENCH_DST.replace("0.7", "abc"), {"wind_pu": "WP4"})


def frame(values: dict[str, list[float]]) -> pd.DataFrame:
    n = len(next(iter(values.values())))
    return pd.DataFrame(values, index=pd.date_range("2016-01-01", periods=n, freq="1min", tz="UTC"))


def test_cleaning_fills_interior_and_end_gaps_and_counts_them():
    filled, counts = fill_gaps_linear(frame({"a": [np.nan, 1.0, np.nan, 3.0, np.nan], "b": [1.0] * 5}))
    assert filled["a"].tolist() == [1.0, 1.0, 2.0, 3.0, 3.0]
    assert counts == {"a": 3, "b": 0}


def test_cleaning_errors_name_file_and_column():
    filled, _ = fill_gaps_linear(frame({"ok": [1.0, 2.0], "empty": [np.nan, np.nan]}))
    with pytest.raises(DataError, match="f.csv: column 'empty' has 2 NaN/inf"):
        check_finite(filled, "f.csv")
    with pytest.raises(DataError, match="f.csv: column 'x' has 1 NaN/inf"):
        check_finite(frame({"x": [1.0, np.inf]}), "f.csv")
    with pytest.raises(DataError, match="f.csv: column 'p' leaves"):
        check_bounds(frame({"p": [0.5, -0.1]}), "f.csv", {"p": (0.0, 1.0)})
    with pytest.raises(DataError, match="f.csv: rating_kw must be a positive"):
        check_rating(-10.0, "f.csv", "rating_kw")
    index = pd.DatetimeIndex(["2016-01-01 00:01", "2016-01-01 00:00"], tz="UTC")
    with pytest.raises(DataError, match="f.csv: column 'time' is not strictly increasing"):
        check_time_index(index, "f.csv")
    with pytest.raises(DataError, match="time-zone-aware"):
        check_time_index(pd.DatetimeIndex(["2016-01-01"]), "f.csv")
    uneven = pd.DatetimeIndex(["2016-01-01 00:00", "2016-01-01 00:01", "2016-01-01 00:03"], tz="UTC")
    with pytest.raises(DataError, match="not evenly spaced"):
        check_time_index(uneven, "f.csv", pd.Timedelta("1min"))
