"""The one JSON writer: every command, benchmark and output file goes through it.

Non-finite floats (NaN, ±inf) become null (JSON has none); numpy scalars and arrays become
plain numbers and lists; paths become strings. Files are written atomically (a temporary
file in the same folder, then rename), so a reader never sees half a file.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import IO

import numpy as np


def json_safe(value: object) -> object:
    """`value` with NaN/inf → None, numpy → Python, tuples → lists, paths → str."""
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        return json_safe(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def dumps(value: object) -> str:
    """Strict JSON text (indent 2) of `json_safe(value)`."""
    return json.dumps(json_safe(value), indent=2, allow_nan=False)


def print_json(value: object, stream: IO[str] | None = None) -> None:
    """Print `value` as strict JSON on stdout (or `stream`)."""
    print(dumps(value), file=stream or sys.stdout)


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Write text or bytes to `path` atomically (temporary file in the same folder + rename)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, value: object) -> Path:
    """Write `value` as strict JSON to `path` atomically."""
    return write_atomic(path, dumps(value) + "\n")
