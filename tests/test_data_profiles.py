"""Profile assembly, the paper day, night masks and the paper-day plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from opfbench.data import (
    PAPER_DAY,
    assemble_profiles,
    load_pv_minute,
    load_simbench_profiles,
    night_mask,
    night_mask_window,
    paper_day,
)
from opfbench.data.plot_paper_day import plot_paper_day
from opfbench.data.profiles import PAPER_DAY_TZ
from opfbench.errors import InputError


def test_paper_day_shape_date_and_ranges():
    day = paper_day()
    assert len(day) == 1440 and day.index.tz is not None
    assert (np.diff(day.index.asi8) == pd.Timedelta("1min").value).all()
    assert pd.Timestamp("2016-06-28") <= pd.Timestamp(PAPER_DAY) <= pd.Timestamp("2016-06-30")
    assert {t.date().isoformat() for t in day.index} == {PAPER_DAY}
    assert day.index[0].hour == 0 and day.index[-1].hour == 23 and day.index[-1].minute == 59
    assert day[["load", "pv", "wind"]].stack().between(0, 1).all()
    assert day["load"].max() == pytest.approx(1.0)
    assert not day.isna().any().any()
    pv_kw = load_pv_minute()["pv_ac_kw"].reindex(day.index.tz_convert("UTC"))
    assert np.allclose(day["pv"], pv_kw.to_numpy() / 10.0)
    assert (day["pv"][night_mask(day.index)] == 0).all() and day["pv"].max() > 0.5


def test_paper_day_resamples_simbench_linearly():
    day = paper_day()
    simbench = load_simbench_profiles()
    quarters = day.index[day.index.minute % 15 == 0]
    native = simbench["wind_pu"].reindex(quarters)
    assert np.allclose(day["wind"].reindex(quarters), native)
    mid = day["wind"].iloc[7]  # 00:07 between 00:00 and 00:15
    assert mid == pytest.approx(native.iloc[0] + 7 / 15 * (native.iloc[1] - native.iloc[0]))
    load = simbench["mv_semiurb_p_pu"].reindex(quarters)
    assert np.allclose(day["load"].reindex(quarters), load / load.max())


def test_assemble_profiles_at_native_15_min_reproduces_simbench():
    index = pd.date_range("2016-01-01", "2016-12-31 23:45", freq="15min", tz="Europe/Berlin")
    profiles = assemble_profiles(index, load_profile="h0a")
    simbench = load_simbench_profiles()
    assert profiles.columns.tolist() == ["load", "pv", "wind"]
    assert np.array_equal(profiles["pv"], simbench["pv_pu"]) and np.array_equal(profiles["wind"], simbench["wind_pu"])
    assert np.allclose(profiles["load"], simbench["h0a_p_pu"] / simbench["h0a_p_pu"].max())
    assert profiles.attrs["load_profile"].endswith(":H0-A_pload")


def test_assemble_profiles_downsamples_bsrn_pv_by_sampling():
    index = pd.date_range("2016-06-10 00:00", periods=96, freq="15min", tz="UTC")
    pv = assemble_profiles(index, pv_source="bsrn")["pv"]
    minute = load_pv_minute()
    assert np.allclose(pv, minute["pv_ac_kw"].reindex(index) / minute.attrs["rating_kw"])


@pytest.mark.parametrize(
    "index, kwargs, message",
    [
        (pd.date_range("2016-06-01", periods=3, freq="1min"), {}, "time-zone-aware"),
        (pd.DatetimeIndex([], tz="UTC"), {}, "non-empty"),
        (pd.DatetimeIndex(["2016-06-01 00:01", "2016-06-01 00:00"], tz="UTC"), {}, "strictly increasing"),
        (pd.date_range("2016-12-31 23:50", periods=20, freq="1min", tz="Europe/Berlin"), {}, "leaves the span"),
        (pd.date_range("2016-07-01 00:00", periods=3, freq="1min", tz="UTC"), {"pv_source": "bsrn"}, "leaves the span"),
        (pd.date_range("2016-06-01", periods=3, freq="1min", tz="UTC"), {"load_profile": "L0-A"}, "unknown load"),
        (pd.date_range("2016-06-01", periods=3, freq="1min", tz="UTC"), {"pv_source": "era5"}, "unknown pv_source"),
    ],
)
def test_assemble_profiles_rejects_bad_windows(index, kwargs, message):
    with pytest.raises(InputError, match=message):
        assemble_profiles(index, **kwargs)


def test_night_mask_follows_sunrise_and_sunset():
    from pvlib.solarposition import sun_rise_set_transit_spa

    index = pd.date_range(PAPER_DAY, periods=1440, freq="1min", tz=PAPER_DAY_TZ)
    night = night_mask(index, 46.8123, 6.9422)
    changes = np.flatnonzero(np.diff(night.to_numpy().astype(int)))
    assert len(changes) == 2 and night.iloc[0] and night.iloc[-1]
    sunrise, sunset = index[changes[0] + 1], index[changes[1] + 1]
    ref = sun_rise_set_transit_spa(index[:1], 46.8123, 6.9422)
    assert abs(sunrise - ref["sunrise"].iloc[0]) < pd.Timedelta("4min")
    assert abs(sunset - ref["sunset"].iloc[0]) < pd.Timedelta("4min")
    tromso = night_mask(index, 69.65, 18.96)  # midnight sun
    assert not tromso.any()


def test_night_mask_window_wraps_midnight():
    index = pd.date_range(PAPER_DAY, periods=1440, freq="1min", tz=PAPER_DAY_TZ)
    night = night_mask_window(index)
    assert night.sum() == 9 * 60
    at = {t: night[pd.Timestamp(f"{PAPER_DAY} {t}", tz=PAPER_DAY_TZ)] for t in ("19:59", "20:00", "04:59", "05:00")}
    assert at == {"19:59": False, "20:00": True, "04:59": True, "05:00": False}
    assert night_mask_window(index, "01:00", "03:00").sum() == 120
    utc = night_mask_window(index.tz_convert("UTC"))  # clock of the index's own zone
    assert utc.sum() == 540 and not utc.equals(night)


@pytest.mark.parametrize(
    "call",
    [
        lambda i: night_mask_window(i, "20:00", "20:00"),
        lambda i: night_mask_window(i, "8pm", "05:00"),
        lambda i: night_mask_window(i.tz_localize(None)),
        lambda i: night_mask(i, 95.0, 0.0),
    ],
)
def test_night_masks_reject_bad_arguments(call):
    with pytest.raises(InputError):
        call(pd.date_range("2016-06-28", periods=10, freq="1min", tz="UTC"))


def test_paper_day_plot(tmp_path):
    out = tmp_path / "day.png"
    plot_paper_day(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    committed = Path(__file__).resolve().parents[1] / "docs" / "paper_day.png"
    assert committed.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
