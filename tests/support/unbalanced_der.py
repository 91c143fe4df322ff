"""Single-phase PV added to a shipped three-phase feeder as OpenDSS PVSystems of a file of
its own (so that opfbench and OpenDSS read the same DER): on every `every`-th load in the
file's load order, on that load's first phase branch (phase to ground or neutral; on a
delta load the phase pair), P̄ = `share` × the load's kW, S̄ = P̄/0.90, fixed kvar 0."""

from __future__ import annotations

from pathlib import Path

from opfbench.io import load_case
from opfbench.multiphase import GROUND, PhaseNetwork


def pv_lines(net: PhaseNetwork, every: int = 2, share: float = 1.0) -> list[str]:
    """The OpenDSS `new pvsystem…` commands of the placement (module docstring)."""
    lb = net.load_branches
    out = []
    for load in range(0, net.n_load, every):
        br = int((lb.owner == load).argmax())
        a, b = int(lb.a[br]), int(lb.b[br])
        bus = net.bus_names[net.node_bus[a]]
        kw = float(share * net.load_p_mw[load] * 1e3)
        if b == GROUND or net.node_phase[b] > 3:
            where = f"bus1={bus}.{net.node_phase[a]} kv={float(lb.vbase_v[br]) / 1e3!r}"
        else:
            where = f"bus1={bus}.{net.node_phase[a]}.{net.node_phase[b]} conn=delta kv={float(lb.vbase_v[br]) / 1e3!r}"
        out.append(
            f"new pvsystem.pv{load} phases=1 {where} pmpp={kw!r} kva={kw / 0.9!r} irradiance=1 kvar=0 vminpu=0.5 vmaxpu=1.5"
        )
    return out


def with_pv(tmp: Path, master: Path, net: PhaseNetwork, every: int = 2, share: float = 1.0) -> Path:
    """A master file that redirects to `master` and adds the PV of `pv_lines`."""
    file = tmp / f"{net.name}_pv.dss"
    file.write_text("\n".join([f'redirect "{master}"', *pv_lines(net, every, share), "calcv"]) + "\n")
    return file


def case_with_pv(tmp: Path, master: Path, name: str, every: int = 2, share: float = 1.0):
    """`load_case` of the shipped feeder `name` with the PV of `pv_lines` (its master
    file, e.g. a copy from `opendss_copy`, at `master`)."""
    base = load_case(name).network
    assert isinstance(base, PhaseNetwork)
    return load_case(f"opendss:{with_pv(tmp, master, base, every, share)}")
