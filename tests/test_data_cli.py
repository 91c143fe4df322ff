"""`opfbench data [--json]`."""

from __future__ import annotations

import json

from opfbench import cli
from opfbench.data import load_pv_minute, load_simbench_profiles, load_wind_hourly


def test_data_json_lists_every_dataset(capsys):
    assert cli.main(["data", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert [d["name"] for d in listing] == ["pv_minute", "wind_hourly", "simbench_profiles"]
    for entry, loaded, step in zip(
        listing, (load_pv_minute(), load_wind_hourly(), load_simbench_profiles()), ("1min", "1h", "15min"), strict=True
    ):
        assert set(entry) == {"name", "rows", "start", "end", "step", "columns", "gaps_filled"}
        assert entry["rows"] == len(loaded) and entry["step"] == step
        assert entry["start"] == loaded.index[0].isoformat() and entry["end"] == loaded.index[-1].isoformat()
        assert entry["columns"] == loaded.attrs["units"] and list(entry["columns"]) == loaded.columns.tolist()
        assert entry["gaps_filled"] == loaded.attrs["gaps_filled"]
    assert listing[0]["gaps_filled"]["dni_wm2"] > 0 and listing[0]["columns"]["pv_ac_kw"] == "kW"


def test_data_text_listing(capsys):
    assert cli.main(["data"]) == 0
    out = capsys.readouterr().out
    assert "pv_minute: 43200 rows" in out and "wind_power_kw" in out and "step 15min" in out
