"""PV on three-phase OpenDSS feeders: the one placement mechanism — a rule that puts a PV
unit beside chosen load elements — used two ways: as opfbench DER (`Placement`s, placed by
`opfbench.io.opendss.place_ders`: the shipped feeders' own rules, `SHIPPED_PLACEMENTS`) and
as OpenDSS PVSystems of a master file of its own (`pv_lines`, `with_pv`, `case_with_pv`;
any network's DER: `pvsystem_lines`),
so that opfbench and OpenDSS read the same DER (the three-phase OPF's tests and its table,
`docs/unbalanced_opf_table.py`).

The rule (`pv_on_loads`): one single-phase unit beside each chosen load, on that load's
first phase branch — phase to the bus's neutral (or ground) for a wye load, between its
phase pair for a delta one — rated P̄ = `kw` kW or, without it, `share` × the load's
nominal kW, S̄ = P̄/0.90 (VDE-AR-N 4105's cos φ 0.90 at full output). Chosen: every
`every`-th load in the file's load order (the first, the `every`+1-th, …), or — with
`fraction` — that share of the single-phase loads (the houses), drawn at random with the
given seed and kept in file order."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from opfbench.io import load_case
from opfbench.io.case import Case
from opfbench.io.opendss import Placement, place_ders
from opfbench.multiphase import GROUND, Branches, PhaseNetwork

PV_PF = 0.90


def pv_on_loads(
    net: PhaseNetwork,
    every: int = 2,
    share: float = 1.0,
    kw: float | None = None,
    fraction: float | None = None,
    seed: int = 0,
) -> tuple[Placement, ...]:
    """The PV of the rule (module docstring) on `net`'s loads."""
    lb = net.load_branches
    if fraction is None:
        chosen = np.arange(0, net.n_load, every)
    else:
        single = np.flatnonzero(np.bincount(lb.owner, minlength=net.n_load) == 1)
        pick = np.random.default_rng(seed).choice(single, size=round(fraction * len(single)), replace=False)
        chosen = np.sort(pick)
    out = []
    for load in chosen.tolist():
        br = int(np.flatnonzero(lb.owner == load)[0])
        a, b = int(lb.a[br]), int(lb.b[br])
        delta = b != GROUND and net.node_phase[b] <= 3
        phases = (int(net.node_phase[a]), int(net.node_phase[b])) if delta else (int(net.node_phase[a]),)
        rated = (share * float(net.load_p_mw[load])) if kw is None else kw / 1e3
        out.append(Placement(net.bus_names[net.node_bus[a]], phases, rated, rated / PV_PF, delta=delta, load=load))
    return tuple(out)


@dataclass(frozen=True)
class PlacementRule:
    """A shipped feeder's DER placement rule: what it says (the case listing and docs) and
    the placements it makes on the feeder's network."""

    text: str
    place: Callable[[PhaseNetwork], tuple[Placement, ...]]


_HALF_EVERY_SECOND = PlacementRule(
    "single-phase PV beside every second load (file order), on its first phase (pair), P̄ = 0.5 × the load's kW, S̄ = P̄/0.90",
    lambda net: pv_on_loads(net, every=2, share=0.5),
)
SHIPPED_PLACEMENTS: dict[str, PlacementRule] = {
    "eulv": PlacementRule(
        "single-phase PV at every second house (LOAD1, LOAD3, …) on the house's phase, P̄ = 4 kW, S̄ = P̄/0.90",
        lambda net: pv_on_loads(net, every=2, kw=4.0),
    ),
    "ckt24": PlacementRule(
        "single-phase PV beside 25 % of the single-phase (residential) loads, drawn with seed 24, P̄ = the load's kW "
        "(its peak: the shapes are normalized), S̄ = P̄/0.90",
        lambda net: pv_on_loads(net, share=1.0, fraction=0.25, seed=24),
    ),
    **dict.fromkeys(("ieee13", "ieee34", "ieee37", "ieee123", "ieee8500", "ckt5", "ckt7"), _HALF_EVERY_SECOND),
}
"""The DER of each shipped feeder (none has PVSystems of its own), applied when no der= is
given; the rule's text is in the case listing."""


def pvsystem_lines(
    net: PhaseNetwork, p_mw: np.ndarray | None = None, q_mvar: np.ndarray | None = None, names: list[str] | None = None
) -> list[str]:
    """The OpenDSS `new pvsystem…` commands of `net`'s DER, each on the nodes of its
    branches: a wye unit from its phases to its neutral (`bus.1.4`; ground: `bus.1`), kV
    its phase-to-neutral base for one phase, phase-to-phase for more; a unit between two
    phases `conn=delta` (`bus.1.2`). Pmpp = P̄, kVA = S̄, fixed output `p_mw`, `q_mvar`
    (n_der,) MW/MVAr (default P̄ and 0) as irradiance P/P̄ and kvar, constant power
    (vminpu 0.5, vmaxpu 1.5), no cut-in; named `names` (default pv1, pv2, … in DER order)."""
    db = net.der_branches
    n = len(net.ders)
    p = np.asarray(net.der_rating_mw if p_mw is None else p_mw, dtype=float)
    q = np.zeros(n) if q_mvar is None else np.asarray(q_mvar, dtype=float)
    out = []
    for d, der in enumerate(net.ders):
        rows = np.flatnonzero(db.owner == d)
        a, b = db.a[rows], db.b[rows]
        phase = [int(net.node_phase[i]) for i in a]
        other = int(b[0])
        delta = len(rows) == 1 and other != GROUND and int(net.node_phase[other]) <= 3
        if len(set(b.tolist())) != 1:
            raise ValueError(f"{net.der_names[d]}: a unit's branches must share their neutral")
        nodes = phase + ([] if other == GROUND else [int(net.node_phase[other])])
        kv = db.vbase_v[rows[0]] / 1e3 * (np.sqrt(3.0) if len(rows) > 1 else 1.0)
        name = f"pv{d + 1}" if names is None else names[d]
        out.append(
            f"new pvsystem.{name} phases={len(rows)} bus1={net.bus_names[der.bus]}.{'.'.join(map(str, nodes))}"
            f"{' conn=delta' if delta else ''} kv={float(kv)!r} pmpp={der.rating_mw * 1e3!r} kva={der.s_rated_mva * 1e3!r} "
            f"irradiance={float(p[d] / der.rating_mw)!r} kvar={float(q[d] * 1e3)!r} %cutin=0 %cutout=0 vminpu=0.5 vmaxpu=1.5"
        )
    return out


def pv_lines(net: PhaseNetwork, every: int = 2, share: float = 1.0, kw: float | None = None) -> list[str]:
    """The OpenDSS `new pvsystem…` commands (`pvsystem_lines`) of the rule
    `pv_on_loads(net, every, share, kw)` on `net` without its DER: PVSystem.pvN beside
    load N (1-based), irradiance 1 and fixed kvar 0 (a snapshot's P and Q are set per
    snapshot)."""
    places = pv_on_loads(net, every, share, kw)
    bare = replace(net, ders=(), der_names=(), der_branches=Branches.empty())
    return pvsystem_lines(place_ders(bare, places, net.name), names=[f"pv{(place.load or 0) + 1}" for place in places])


def with_pv(folder: Path, master: Path, net: PhaseNetwork, every: int = 2, share: float = 1.0, kw: float | None = None) -> Path:
    """A master file in `folder` that redirects to `master` and adds the PV of `pv_lines`."""
    file = folder / f"{net.name}_pv.dss"
    file.write_text("\n".join([f'redirect "{master}"', *pv_lines(net, every, share, kw), "calcv"]) + "\n")
    return file


def case_with_pv(
    folder: Path, master: Path, name: str, every: int = 2, share: float = 1.0, kw: float | None = None, taps: str = "held"
) -> Case:
    """The shipped feeder `name` (its master file, e.g. a copy from `opendss_copy`, at
    `master`) with the PV of `pv_lines`, read by `load_case` with the case option
    `taps=` `taps` (held where OpenDSS settles the file, or control: `opfbench.io.spec`)."""
    base = load_case(name).network
    if not isinstance(base, PhaseNetwork):
        raise TypeError(f"{name} is not a three-phase feeder")
    return load_case(f"opendss:{with_pv(folder, master, base, every, share, kw)}?taps={taps}")
