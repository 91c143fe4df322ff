"""The shipped unbalanced feeders: OpenDSS models in the package (`cases/opendss/`, copied
by `opfbench.cases.derive_opendss`, BSD-3, provenance beside them), read through the
`opendss:` source like any user's file.

| name | feeder |
|---|---|
| `ieee13` | IEEE 13 node test feeder (4.16 kV; delta and wye loads of models 1, 2, 5; three single-phase regulators) |
| `ieee34` | IEEE 34 node test feeder, Mod 1 (24.9 kV; two regulator banks) |
| `ieee37` | IEEE 37 node test feeder (4.8 kV three-wire delta; open-delta regulators) |
| `ieee123` | IEEE 123 node test feeder (4.16 kV; switches, seven regulators) |
| `eulv` | IEEE European LV test feeder (416 V, 50 Hz, 55 single-phase houses) |
| `ieee8500` | IEEE 8500-node test feeder (12.47 kV, 120/240 V split-phase secondaries; balanced loads) |
| `ckt5`, `ckt7`, `ckt24` | EPRI test circuits 5, 7 and 24 (ckt24 with its 8760-h load shapes) |
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

OPENDSS_CASES: dict[str, tuple[str, str]] = {
    # name: (folder in cases/opendss, master file)
    "ieee13": ("ieee13", "IEEE13Nodeckt.dss"),
    "ieee34": ("ieee34", "ieee34Mod1.dss"),
    "ieee37": ("ieee37", "ieee37.dss"),
    "ieee123": ("ieee123", "IEEE123Master.dss"),
    "eulv": ("eulv", "Master.dss"),
    "ieee8500": ("ieee8500", "Master.dss"),
    "ckt5": ("ckt5", "Master_ckt5.dss"),
    "ckt7": ("ckt7", "Master_ckt7.dss"),
    "ckt24": ("ckt24", "master_ckt24.dss"),
}
OPENDSS_NAMES = tuple(OPENDSS_CASES)


def _root() -> Path:
    return Path(str(resources.files("opfbench.cases") / "opendss"))


def opendss_master(name: str) -> Path:
    """The shipped master file of the feeder `name` (one of OPENDSS_NAMES)."""
    folder, master = OPENDSS_CASES[name]
    return _root() / folder / master


@contextmanager
def opendss_copy(name: str) -> Iterator[Path]:
    """The master file of a temporary copy of the shipped feeder `name` (its folder and the
    files it reads from the parent folder): OpenDSS writes some files beside the model it
    compiles (a RegControl's `debugtrace`), never into the installed package."""
    folder, master = OPENDSS_CASES[name]
    root = _root()
    with tempfile.TemporaryDirectory(prefix=f"opfbench-{name}-") as tmp:
        shutil.copytree(root / folder, Path(tmp) / folder)
        for shared in root.glob("*.DSS"):
            shutil.copyfile(shared, Path(tmp) / shared.name)
        yield Path(tmp) / folder / master
