"""Damaging a study folder's checkpoints the ways a crash, a full disk or a careless copy
would, for the resume tests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

KINDS = ("is truncated", "is empty", "holds another task's rows", "is partly missing", "has other columns")
"""What `damage` does to five checkpoints, as the store's notes say it."""


def damage(out: Path, side: str) -> list[str]:
    """Truncate the first task's checkpoint, empty the second's, copy the seventh's over
    the third's, delete the fourth's `side` table and add a column to the fifth's (as
    another version would write it, its tags kept) — tasks as the manifest lists them; the
    damaged checkpoints' file names (tasks/…), in that order."""
    files = [t["file"] for t in json.loads((out / "manifest.json").read_text())["tasks"]]
    truncated, empty, foreign, cut, other = (out / f for f in files[:5])
    truncated.write_bytes(truncated.read_bytes()[:-100])
    empty.write_bytes(b"")
    shutil.copy(out / files[6], foreign)
    cut.with_name(cut.name.removesuffix(".parquet") + f".{side}.parquet").unlink()
    table = pq.read_table(other)
    pq.write_table(
        table.append_column("extra", pa.array([0.0] * table.num_rows)).replace_schema_metadata(table.schema.metadata), other
    )
    return files[:5]
