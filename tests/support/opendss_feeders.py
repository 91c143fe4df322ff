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
    return _snapshot()


def _snapshot() -> DssSnapshot:
    return DssSnapshot(
        [n.lower() for n in dss.Circuit.AllNodeNames()],
        np.asarray(dss.Circuit.AllBusVolts()).view(complex),
        np.asarray(dss.Circuit.AllBusMagPu()),
        float(dss.Circuit.Losses()[0]) / 1e3,
        bool(dss.Solution.Converged()),
    )


def _settled_and_held(master: Path):
    """Compile `master` and solve its snapshot with the control loop on (regulator taps and
    capacitors settle, as opfbench's reader finds them), then hold them (RegControls and
    CapControls disabled); returns OpenDSS's command function."""
    dss.Basic.AllowChangeDir(False)
    run = dss.Text.Command
    run("clear")
    run(f'compile "{master}"')
    run(f"set mode=snapshot tolerance={TOLERANCE!r} maxiterations=200")
    dss.Solution.Solve()
    assert dss.Solution.Converged()
    run("batchedit regcontrol..* enabled=no")
    run("batchedit capcontrol..* enabled=no")
    return run


def solve_time_step(master: Path, pv_lines: list[str], load_mult: float | None = None, hour: float | None = None) -> DssSnapshot:
    """OpenDSS at one time-series step of a shipped feeder with DER at fixed output: the
    file's snapshot settled and held (`_settled_and_held`), the PVSystems `pv_lines` added, and one solution — in snapshot mode at `load_mult` (the loads ×
    a load profile's value), or in yearly mode at `hour` (each load on its own yearly
    shape: OpenDSS reads a fixed-interval shape's point k (1-based) at hour k × interval)."""
    run = _settled_and_held(master)
    for line in pv_lines:
        run(line)
    if hour is None:
        run(f"set loadmult={load_mult!r}")
    else:
        start = hour * 3600.0 - 60.0  # a time mode moves the clock one step (here 1 min) before it solves
        run("set mode=yearly number=1 stepsize=60s")
        dss.Solution.Hour(int(start // 3600))
        dss.Solution.Seconds(start % 3600)
    run(f"set tolerance={TOLERANCE!r} maxiterations=200")
    dss.Solution.Solve()
    if hour is not None:
        assert abs(dss.Solution.DblHour() - hour) < 1e-9, (dss.Solution.DblHour(), hour)
    return _snapshot()


def pv_output() -> np.ndarray:
    """(n_pv, 2) every PVSystem's kW and kvar generated at the last solution (circuit order)."""
    out = []
    for name in dss.PVsystems.AllNames():
        dss.Circuit.SetActiveElement(f"pvsystem.{name}")
        powers = np.asarray(dss.CktElement.Powers())
        out.append((-powers[0::2].sum(), -powers[1::2].sum()))
    return np.array(out).reshape(-1, 2)


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


@dataclass(frozen=True)
class InverterAnswer:
    """OpenDSS's closed-loop steady state with InvControls: each PVSystem's P and Q (MW,
    MVAr, generated, in the order given), node names and |V| p.u., whether the solution
    and its control loop converged."""

    p_mw: np.ndarray
    q_mvar: np.ndarray
    node_names: list[str]
    vm_pu: np.ndarray
    converged: bool


TIGHT = "varchangetolerance=1e-10 voltagechangetolerance=1e-10 activepchangetolerance=1e-10 eventlog=no"


def volt_var(
    master: Path,
    load_mult: float,
    units: list[tuple[str, float, float, float, float]],
    curve_v: tuple[float, ...],
    curve_q: list[np.ndarray],
) -> InverterAnswer:
    """OpenDSS's Volt-VAR steady state on a shipped feeder: compiled and solved at its own
    loads (regulator taps settle), taps then held (RegControls and CapControls disabled),
    loads × `load_mult`, and one PVSystem per unit (bus1 with nodes, e.g. `34.1.0`; kV; kVA;
    Pmpp kW; P kW) — constant power (vminpu 0.05) — each with an InvControl VOLTVAR
    (adaptive step, tight tolerances, measured voltage the phases' average, the rated
    voltage as the curve's reference), curve `curve_v` → `curve_q[i]` in p.u. of its
    kvarMax (= |Q| limit: kvarmax is its last entry), flat beyond the ends."""
    far = (0.5, 1.5)
    run = _settled_and_held(master)
    run(f"set loadmult={load_mult!r}")
    for i, ((bus1, kv, kva, pmpp, p_kw), (q_pu, kvar_max)) in enumerate(zip(units, curve_q, strict=True)):
        phases = len(bus1.split(".")) - 2
        xs, ys = (far[0], *curve_v, far[1]), (q_pu[0], *q_pu, q_pu[-1])
        run(
            f"new xycurve.vv{i} npts={len(xs)} xarray=[{' '.join(map(repr, map(float, xs)))}] yarray=[{' '.join(map(repr, map(float, ys)))}]"
        )
        run(
            f"new pvsystem.pv{i} phases={phases} bus1={bus1} kv={kv!r} kva={kva!r} pmpp={pmpp!r} irradiance={p_kw / pmpp!r} "
            f"%cutin=0 %cutout=0 kvarmax={kvar_max!r} kvarmaxabs={kvar_max!r} wattpriority=no pfpriority=no "
            "varfollowinverter=no vminpu=0.05 vmaxpu=2"
        )
        run(
            f"new invcontrol.ic{i} derlist=[pvsystem.pv{i}] mode=voltvar vvc_curve1=vv{i} voltage_curvex_ref=rated "
            f"refreactivepower=varmax deltaq_factor=-1 {TIGHT}"
        )
    run("set controlmode=static maxcontroliter=5000")
    dss.Solution.Solve()
    p, q = np.zeros(len(units)), np.zeros(len(units))
    for i in range(len(units)):
        dss.Circuit.SetActiveElement(f"pvsystem.pv{i}")
        powers = np.asarray(dss.CktElement.Powers())
        p[i], q[i] = -powers[0::2].sum() / 1e3, -powers[1::2].sum() / 1e3  # kW, kvar into the element
    return InverterAnswer(
        p,
        q,
        [n.lower() for n in dss.Circuit.AllNodeNames()],
        np.asarray(dss.Circuit.AllBusMagPu()),
        bool(dss.Solution.Converged()),
    )


def held_taps(net: PhaseNetwork) -> list[str]:
    """OpenDSS commands holding every regulator at the tap our model read."""
    out = []
    for t in net.transformers:
        if t.regulated:
            name = net.elements[t.element].name.split(".", 1)[1]
            out += [set_tap(name, w + 1, wdg.tap) for w, wdg in enumerate(t.windings)]
    return out
