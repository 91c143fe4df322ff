"""Damaging a study folder's checkpoints the ways a crash, a full disk or a careless copy
would, for the resume tests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

KINDS = ("is truncated", "is empty", "holds another task's rows", "is partly missing")
"""What `damage` does to four checkpoints, as the store's notes say it."""


def damage(out: Path, side: str) -> list[str]:
    """Truncate the first task's checkpoint, empty the second's, copy the sixth's over the
    third's and delete the fourth's `side` table (tasks as the manifest lists them); the
    damaged checkpoints' file names (tasks/…), in that order."""
    files = [t["file"] for t in json.loads((out / "manifest.json").read_text())["tasks"]]
    truncated, empty, foreign, cut = (out / f for f in files[:4])
    truncated.write_bytes(truncated.read_bytes()[:-100])
    empty.write_bytes(b"")
    shutil.copy(out / files[5], foreign)
    cut.with_name(cut.name.removesuffix(".parquet") + f".{side}.parquet").unlink()
    return files[:4]
