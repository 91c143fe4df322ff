"""Deterministic storage of the derived series: gzipped CSV + one JSON manifest.

Every file is written so that the same input gives the same bytes: a ``time_utc``
column ``YYYY-MM-DD HH:MM`` (UTC), each value column rounded to a stated number of
decimals and printed in Python's shortest round-trip form, gzip level 9 with no file
name and a zero modification time; the manifest is indented JSON in a fixed key order.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd

from opfbench.errors import DataError
from opfbench.jsonio import write_atomic, write_json

#: The folder of the embedded derived files.
FILES_DIR = Path(__file__).parent / "files"
MANIFEST = "manifest.json"
TIME_COLUMN = "time_utc"
_TIME_FORMAT = "%Y-%m-%d %H:%M"


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_series_csv_gz(df: pd.DataFrame, path: Path, decimals: dict[str, int]) -> None:
    """Write ``df`` (tz-aware index at whole minutes) to ``path`` reproducibly, rounding
    each column to ``decimals[column]`` places."""
    table = pd.DataFrame({TIME_COLUMN: df.index.tz_convert("UTC").strftime(_TIME_FORMAT)})
    for col in df.columns:
        table[col] = np.round(df[col].to_numpy(dtype=float), decimals[col]) + 0.0  # no "-0.0"
    text = table.to_csv(index=False, lineterminator="\n")
    buffer = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buffer, compresslevel=9, mtime=0) as gz:
        gz.write(text.encode("ascii"))
    write_atomic(path, buffer.getvalue())


def read_series_csv_gz(path: Path, tz: str) -> pd.DataFrame:
    """Read a file written by `write_series_csv_gz`; the index is converted to ``tz``."""
    try:
        table = pd.read_csv(path, compression="gzip")
        index = pd.to_datetime(table.pop(TIME_COLUMN), format=_TIME_FORMAT, utc=True)
    except (OSError, KeyError, ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: unreadable derived series ({exc})") from exc
    return table.set_index(pd.DatetimeIndex(index).tz_convert(tz)).astype(float)


def write_manifest(manifest: dict, folder: Path) -> None:
    """Write the manifest as indented JSON (keys in insertion order) with a final newline."""
    write_json(Path(folder) / MANIFEST, manifest)


def read_manifest(folder: Path) -> dict:
    """Read the manifest of a derived-files folder."""
    path = Path(folder) / MANIFEST
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: unreadable manifest ({exc})") from exc
