"""An on-disk cache of converted cases whose source is slow to read: simbench extracts a
grid from its complete data set slowly, OpenDSS compiles, solves and hands over a large
feeder element by element slowly; the conversion is quick. The first
read of a spec writes the converted case (network, stored point, series, notes) to
`$OPFBENCH_CACHE` (default `$XDG_CACHE_HOME/opfbench`, else `~/.cache/opfbench`); later
processes — every Dask worker, every `opfbench pf` — read it back at once.

An entry is keyed by the spec and everything that could change the result: the
simbench, pandapower, OpenDSS and numpy versions, a hash of the converters' own source
files and the caller's stamp of the source (a file's path, time and size). It is rebuilt
through the constructors of its records (so the network is checked and read-only again),
written atomically, and an unreadable entry is ignored and rewritten. `OPFBENCH_CACHE=off`
turns the cache off.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import importlib.metadata as md
import os
import pickle
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

from opfbench.io.case import Case

#: Source files whose change invalidates every entry (the conversion and the records).
_SOURCES = (
    "io/pandapower.py",
    "io/simbench.py",
    "io/opendss.py",
    "io/case.py",
    "io/disk_cache.py",
    "network.py",
    "multiphase/model.py",
    "multiphase/branches.py",
    "multiphase/regulators.py",
    "data/simbench_profiles.py",
)
_FORMAT = 2
_RECORD = "__record__"


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
    for package in ("simbench", "pandapower", "numpy", "opendssdirect.py", "dss-python"):
        try:
            digest.update(f"{package}={md.version(package)}".encode())
        except md.PackageNotFoundError:
            digest.update(f"{package}=none".encode())
    return digest.hexdigest()[:16]


def _state(value: object) -> object:
    """`value` with every opfbench record (a dataclass) as {_RECORD: its class, fields…},
    tuples and lists item by item; the case's own fields stay the top-level dict."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _state(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return fields if isinstance(value, Case) else {_RECORD: f"{type(value).__module__}:{type(value).__qualname__}"} | fields
    if isinstance(value, (tuple, list)):
        return type(value)(_state(v) for v in value)
    return value


def _build(state: object) -> object:
    """The value `_state` wrote, every record rebuilt through its constructor (only
    opfbench's own records)."""
    if isinstance(state, dict) and _RECORD in state:
        module, _, name = str(state[_RECORD]).partition(":")
        if not module.startswith("opfbench."):
            raise TypeError(f"not an opfbench record: {module}")
        cls = getattr(importlib.import_module(module), name)
        return cls(**{k: _build(v) for k, v in state.items() if k != _RECORD})
    if isinstance(state, (tuple, list)):
        return type(state)(_build(v) for v in state)
    return state


def _case(state: dict) -> Case:
    fields: dict[str, Any] = {k: _build(v) for k, v in state.items()}
    return Case(**fields)


def cached_case(spec: str, build: Callable[[], Case], stamp: tuple = ()) -> Case:
    """The case of `spec` from the cache, else `build()` (and written to the cache);
    `stamp` identifies the source's state (e.g. a file's path, time and size)."""
    folder = cache_dir()
    if folder is None:
        return build()
    safe = "".join(c if c.isalnum() or c in "-._" else "_" for c in spec)[:80]
    key = hashlib.sha256(f"{spec}|{stamp!r}|{_code_hash()}".encode()).hexdigest()[:16]
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
