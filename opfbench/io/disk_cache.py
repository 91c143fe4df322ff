"""An on-disk cache of converted cases whose source is slow to read: simbench extracts a
grid from its complete data set slowly, the conversion is quick. The first
read of a spec writes the converted case (network, stored point, series, notes) to
`$OPFBENCH_CACHE` (default `$XDG_CACHE_HOME/opfbench`, else `~/.cache/opfbench`); later
processes — every Dask worker, every `opfbench pf` — read it back at once.

An entry is keyed by the spec and everything that could change the result: the
simbench, pandapower and numpy versions and a hash of the converter's own source files.
It is rebuilt through the constructors (so the network is checked and read-only again),
written atomically, and an unreadable entry is ignored and rewritten. `OPFBENCH_CACHE=off`
turns the cache off.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata as md
import os
import pickle
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Callable

from opfbench.io.case import Case, CaseSeries
from opfbench.network import Network

#: Source files whose change invalidates every entry (the conversion and the records).
_SOURCES = ("io/pandapower.py", "io/simbench.py", "io/case.py", "io/disk_cache.py", "network.py", "data/simbench_profiles.py")
_FORMAT = 1


def cache_dir() -> Path | None:
    """The cache folder, or None when `OPFBENCH_CACHE=off`."""
    where = os.environ.get("OPFBENCH_CACHE")
    if where == "off":
        return None
    if where:
        return Path(where)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "opfbench"


@lru_cache(maxsize=1)
def _code_hash() -> str:
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.sha256(str(_FORMAT).encode())
    for name in _SOURCES:
        digest.update((root / name).read_bytes())
    for package in ("simbench", "pandapower", "numpy"):
        try:
            digest.update(f"{package}={md.version(package)}".encode())
        except md.PackageNotFoundError:
            digest.update(f"{package}=none".encode())
    return digest.hexdigest()[:16]


def _state(case: Case) -> dict:
    fields = {f.name: getattr(case, f.name) for f in dataclasses.fields(case)}
    fields["network"] = {f.name: getattr(case.network, f.name) for f in dataclasses.fields(case.network)}
    if case.series is not None:
        fields["series"] = {f.name: getattr(case.series, f.name) for f in dataclasses.fields(case.series)}
    return fields


def _case(state: dict) -> Case:
    state = dict(state)
    state["network"] = Network(**state["network"])
    if state.get("series") is not None:
        state["series"] = CaseSeries(**state["series"])
    return Case(**state)


def cached_case(spec: str, build: Callable[[], Case]) -> Case:
    """The case of `spec` from the cache, else `build()` (and written to the cache)."""
    folder = cache_dir()
    if folder is None:
        return build()
    safe = "".join(c if c.isalnum() or c in "-._" else "_" for c in spec)[:80]
    key = hashlib.sha256(f"{spec}|{_code_hash()}".encode()).hexdigest()[:16]
    path = folder / f"{safe}-{key}.pickle"
    try:
        with path.open("rb") as fh:
            return _case(pickle.load(fh))
    except FileNotFoundError:
        pass
    except Exception:  # noqa: BLE001 — a damaged or foreign entry is rebuilt, never trusted
        path.unlink(missing_ok=True)
    case = build()
    tmp = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            pickle.dump(_state(case), fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)
    except OSError:  # a read-only or full disk: the case is still returned, just not kept
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
    return case
