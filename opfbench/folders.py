"""Output folders, checked before any work: an `--out` that is a file, cannot be created or
cannot be written is one InputError naming it (exit code 2), never a traceback after the
computation."""

from __future__ import annotations

from pathlib import Path

from opfbench.errors import InputError

_PROBE = ".opfbench-write-test"


def check_out_dir(directory: str | Path) -> Path:
    """`directory` as a writable folder (created with its parents if missing)."""
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / _PROBE
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"--out {out}: cannot write there ({exc.strerror})") from None
    return out
