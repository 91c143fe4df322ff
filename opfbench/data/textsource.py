"""Read a raw data file given either as a path or as its text (for tests on small inputs)."""

from __future__ import annotations

import gzip
import os
from pathlib import Path

from opfbench.errors import DataError

Source = str | os.PathLike


def read_source(source: Source) -> tuple[str, str]:
    """Return ``(text, name)``. A ``str`` containing a newline is taken as the file's text
    (name ``"<text>"``); anything else is a path, gunzipped when it ends in ``.gz``."""
    if isinstance(source, str) and "\n" in source:
        return source, "<text>"
    path = Path(source)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from exc
    if path.suffix == ".gz":
        raw = gzip.decompress(raw)
    return raw.decode("utf-8"), str(path)
