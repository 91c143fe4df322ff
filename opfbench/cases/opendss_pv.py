"""Single-phase PV added to a three-phase OpenDSS feeder as PVSystems of a master file of
its own, so that opfbench and OpenDSS read the same DER (the three-phase OPF's tests and
its table, `docs/unbalanced_opf_table.py`).

The placement: on every `every`-th load in the file's load order (the first, the
`every`+1-th, …), one PVSystem on that load's first phase branch (phase to ground or
neutral; on a delta load its phase pair), rated P̄ = `kw` kW or, without it, `share` × the
load's nominal kW, S̄ = P̄/0.90 (VDE-AR-N 4105's cos φ 0.90 at full output), irradiance 1
and fixed kvar 0 (a snapshot's P and Q are set per snapshot)."""

from __future__ import annotations

from pathlib import Path

from opfbench.io import load_case
from opfbench.io.case import Case
from opfbench.multiphase import GROUND, PhaseNetwork


def pv_lines(net: PhaseNetwork, every: int = 2, share: float = 1.0, kw: float | None = None) -> list[str]:
    """The OpenDSS `new pvsystem…` commands of the placement (module docstring)."""
    lb = net.load_branches
    out = []
    for load in range(0, net.n_load, every):
        br = int((lb.owner == load).argmax())
        a, b = int(lb.a[br]), int(lb.b[br])
        bus = net.bus_names[net.node_bus[a]]
        rated = float(share * net.load_p_mw[load] * 1e3) if kw is None else float(kw)
        kv = float(lb.vbase_v[br]) / 1e3
        if b == GROUND or net.node_phase[b] > 3:
            where = f"bus1={bus}.{net.node_phase[a]} kv={kv!r}"
        else:
            where = f"bus1={bus}.{net.node_phase[a]}.{net.node_phase[b]} conn=delta kv={kv!r}"
        out.append(
            f"new pvsystem.pv{load + 1} phases=1 {where} pmpp={rated!r} kva={rated / 0.9!r} irradiance=1 kvar=0 vminpu=0.5 vmaxpu=1.5"
        )
    return out


def with_pv(folder: Path, master: Path, net: PhaseNetwork, every: int = 2, share: float = 1.0, kw: float | None = None) -> Path:
    """A master file in `folder` that redirects to `master` and adds the PV of `pv_lines`."""
    file = folder / f"{net.name}_pv.dss"
    file.write_text("\n".join([f'redirect "{master}"', *pv_lines(net, every, share, kw), "calcv"]) + "\n")
    return file


def case_with_pv(folder: Path, master: Path, name: str, every: int = 2, share: float = 1.0, kw: float | None = None) -> Case:
    """The shipped feeder `name` (its master file, e.g. a copy from `opendss_copy`, at
    `master`) with the PV of `pv_lines`, read by `load_case`."""
    base = load_case(name).network
    if not isinstance(base, PhaseNetwork):
        raise TypeError(f"{name} is not a three-phase feeder")
    return load_case(f"opendss:{with_pv(folder, master, base, every, share, kw)}")
