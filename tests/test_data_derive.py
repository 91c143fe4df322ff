"""The derivation regenerates the embedded files byte for byte, and the manifest's gap
counts are those of the raw files. Needs the raw public sources, given by the environment
variable OPFBENCH_RAW_DATA (e.g. ``OPFBENCH_RAW_DATA=../shared/data python -m pytest
tests/test_data_derive.py``); the default suite never reads outside the project."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from opfbench.data.bsrn import parse_bsrn_lr0100
from opfbench.data.derive import BSRN_FILE, TRY_FILE, derive_all
from opfbench.data.dwd_try import parse_try
from opfbench.data.files_io import FILES_DIR, sha256

RAW = Path(os.environ.get("OPFBENCH_RAW_DATA", "")).resolve()
pytestmark = pytest.mark.skipif(
    "OPFBENCH_RAW_DATA" not in os.environ,
    reason="set OPFBENCH_RAW_DATA to the raw data folder to check the derivation byte for byte",
)
DERIVED = sorted(p.name for p in FILES_DIR.iterdir() if p.suffix in {".gz", ".json", ".txt"})


@pytest.fixture(scope="module")
def rederived(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("derived")
    derive_all(RAW, out)
    return out


def test_derivation_writes_exactly_the_embedded_files(rederived):
    assert sorted(p.name for p in rederived.iterdir()) == DERIVED
    assert len(DERIVED) == 5


@pytest.mark.parametrize("name", DERIVED)
def test_derivation_is_bit_for_bit(rederived, name):
    assert sha256(rederived / name) == sha256(FILES_DIR / name), f"{name} differs: rerun python -m opfbench.data.derive"


def test_manifest_gap_counts_are_the_raw_missing_values():
    gaps = {
        name: entry["gaps_filled"] for name, entry in json.loads((FILES_DIR / "manifest.json").read_text())["datasets"].items()
    }
    for name, raw in (("pv_minute", parse_bsrn_lr0100(RAW / BSRN_FILE)), ("wind_hourly", parse_try(RAW / TRY_FILE))):
        missing = raw.isna().sum().to_dict()
        assert {col: gaps[name][col] for col in raw.columns} == missing
    assert sum(gaps["pv_minute"].values()) > 0  # the BSRN month does have gaps
