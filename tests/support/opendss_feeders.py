"""OpenDSS (through `opendssdirect.py`) as the test-time oracle of the three-phase model:
a master file compiled and solved by OpenDSS on its own — nothing of opfbench's reader —
and what it reports: node names and voltages, circuit losses, sequence voltages.

`UNBALANCED_SMALL` are the shipped feeders the default suite checks; `UNBALANCED_ALL`
every shipped one (`-m slow`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import opendssdirect as dss

from opfbench.multiphase import PhaseNetwork

UNBALANCED_SMALL = ("ieee13", "ieee34", "ieee37", "ieee123", "eulv")
UNBALANCED_ALL = UNBALANCED_SMALL + ("ieee8500", "ckt5", "ckt7", "ckt24")
TOLERANCE = 1e-10


@dataclass(frozen=True)
class DssSnapshot:
    """What OpenDSS solved: node names (lower case, its order), complex node voltages (V),
    node |V| in p.u. of the node's base, circuit losses (kW), whether it converged."""

    node_names: list[str]
    v: np.ndarray
    vm_pu: np.ndarray
    losses_kw: float
    converged: bool


def solve(master: Path, *commands: str, controls: bool = True) -> DssSnapshot:
    """Compile `master`, run `commands` (e.g. `set loadmult=1.3`, `new pvsystem…`), solve
    one snapshot at tolerance TOLERANCE (control loop on unless `controls` is False: then
    regulator taps and capacitor states stay where the compile left them)."""
    dss.Basic.AllowChangeDir(False)
    dss.Text.Command("clear")
    dss.Text.Command(f'compile "{master}"')
    for command in commands:
        dss.Text.Command(command)
    dss.Text.Command(f"set mode=snapshot tolerance={TOLERANCE!r} maxiterations=200")
    if not controls:
        dss.Text.Command("set controlmode=off")
    dss.Solution.Solve()
    names = [n.lower() for n in dss.Circuit.AllNodeNames()]
    return DssSnapshot(
        names,
        np.asarray(dss.Circuit.AllBusVolts()).view(complex),
        np.asarray(dss.Circuit.AllBusMagPu()),
        float(dss.Circuit.Losses()[0]) / 1e3,
        bool(dss.Solution.Converged()),
    )


def bus_vuf(bus: str) -> float:
    """OpenDSS's |V₂|/|V₁| at `bus` of the last solution (its sequence voltages)."""
    dss.Circuit.SetActiveBus(bus)
    seq = np.asarray(dss.Bus.SeqVoltages())  # |V0|, |V1|, |V2|
    return float(seq[2] / seq[1])


def line_impedance_ohm(name: str) -> np.ndarray:
    """OpenDSS's own series impedance matrix of line `name` (its R and X matrices per
    unit length × length, in Ω) after the last compile."""
    dss.Lines.Name(name)
    n = dss.Lines.Phases()
    r = np.asarray(dss.Lines.RMatrix()).reshape(n, n)
    x = np.asarray(dss.Lines.XMatrix()).reshape(n, n)
    return (r + 1j * x) * dss.Lines.Length()


def set_tap(transformer: str, winding: int, tap: float) -> str:
    """The OpenDSS command that puts a transformer's winding at `tap` p.u."""
    return f"transformer.{transformer}.wdg={winding} tap={tap!r}"


def held_taps(net: PhaseNetwork) -> list[str]:
    """OpenDSS commands holding every regulator at the tap our model read."""
    out = []
    for t in net.transformers:
        if t.regulated:
            name = net.elements[t.element].name.split(".", 1)[1]
            out += [set_tap(name, w + 1, wdg.tap) for w, wdg in enumerate(t.windings)]
    return out
