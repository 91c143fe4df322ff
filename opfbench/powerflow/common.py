"""What every power-flow solver shares: tolerances, the result record, bus injections
and the dense/sparse choice.

Inputs are net complex bus injections in MW/MVAr (generation minus load, positive =
into the grid). Results carry complex bus voltages (p.u.), branch flows at both ends
(MW/MVAr, positive = leaving the bus into the branch) and total losses (kW).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from typing import Self

import numpy as np

from opfbench.errors import InputError
from opfbench.network import Network

NR_TOLERANCE = 1e-9  # p.u. largest P/Q mismatch (Newton–Raphson)
SWEEP_TOLERANCE = 1e-10  # p.u. largest voltage update (batched fixed point)
MISMATCH_CHECK = 1e-8  # p.u.; a batched snapshot whose mismatch exceeds this goes to NR
MAX_NR_ITER = 30
MAX_SWEEP_ITER = 200
# Feeders with at least this many buses use the sparse solvers (scipy.sparse, SuperLU);
# smaller ones the dense ones: on paper33 the dense kernels are the faster, on case141 the
# sparse ones, in between they are close (`python -m opfbench.bench pf` times both). The
# dense Z-bus also costs 16·n² bytes (1.6 GB at 10 000 buses).
SPARSE_MIN_BUSES = 100


def uses_sparse(net: Network) -> bool:
    """True when `net` is solved by the sparse solvers (n_bus ≥ SPARSE_MIN_BUSES)."""
    return net.n_bus >= SPARSE_MIN_BUSES


@dataclass(frozen=True, eq=False)
class PowerFlowResult:
    """Solution of one snapshot (arrays shaped (n_bus,), converged and iterations numpy
    scalars) or of a batch ((S, n_bus), (S,))."""

    net: Network
    v: np.ndarray
    converged: np.ndarray  # bool, (S,) or 0-d for one snapshot
    iterations: np.ndarray  # int64, likewise

    @property
    def vm(self) -> np.ndarray:
        return np.abs(self.v)

    def with_converged(self, converged: np.ndarray) -> Self:
        """The same voltages with the verdict `converged` (S,) (e.g. a strategy's own: a
        snapshot one of whose earlier flows diverged)."""
        return replace(self, converged=np.asarray(converged, dtype=bool))

    @cached_property
    def _flows(self) -> tuple[np.ndarray, np.ndarray]:
        yff, yft, ytf, ytt = self.net.branch_admittances
        vf, vt = self.v[..., self.net.f], self.v[..., self.net.t]
        base = self.net.base_mva
        with np.errstate(all="ignore"):  # a diverged snapshot's iterate may overflow; it carries no figure
            sf = vf * np.conj(yff * vf + yft * vt) * base
            st = vt * np.conj(ytf * vf + ytt * vt) * base
        return sf, st

    @property
    def sf_mva(self) -> np.ndarray:
        """Complex power entering each branch at its from end (MW + jMVAr)."""
        return self._flows[0]

    @property
    def st_mva(self) -> np.ndarray:
        """Complex power entering each branch at its to end (MW + jMVAr)."""
        return self._flows[1]

    @cached_property
    def losses_kw(self) -> np.ndarray:
        """Total series + charging active losses over all branches (kW)."""
        sf, st = self._flows
        with np.errstate(all="ignore"):
            return (sf + st).real.sum(axis=-1) * 1e3

    @property
    def slack_s_mva(self) -> np.ndarray:
        """Complex power injected by the slack bus into the grid (MW + jMVAr)."""
        s = self.net.slack
        row = self.net.ybus_sparse[s]  # (1, n_bus) sparse
        current = (row @ np.atleast_2d(self.v).T)[0]
        return self.v[..., s] * np.conj(current.reshape(self.v.shape[:-1])) * self.net.base_mva

    def extreme_voltage(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """(|V| p.u., external bus number) of the lowest ('min') or highest ('max') voltage."""
        vm = self.vm
        k = vm.argmin(axis=-1) if which == "min" else vm.argmax(axis=-1)
        return np.take_along_axis(vm, np.expand_dims(k, -1), -1).squeeze(-1), self.net.bus_ids[k]


def bus_injections(
    net: Network,
    der_p_mw: np.ndarray | float = 0.0,
    der_q_mvar: np.ndarray | float = 0.0,
    load_scale: np.ndarray | float = 1.0,
    bus_load_mva: np.ndarray | None = None,
) -> np.ndarray:
    """Net complex injection per bus (MW + jMVAr): fixed gens + DER − load.

    The load is `load_scale`·(nominal load), or `bus_load_mva` (S, n_bus) complex MVA
    when given (e.g. the per-load P and Q of a real grid summed onto the buses;
    `load_scale` is then ignored). `der_p_mw`/`der_q_mvar` are shaped (n_der,) or
    (S, n_der); `load_scale` is a scalar or (S,). Returns (n_bus,) or (S, n_bus).
    """
    der_s = np.asarray(der_p_mw, dtype=float) + 1j * np.asarray(der_q_mvar, dtype=float)
    scale = np.asarray(load_scale, dtype=float)
    for label, arr in (("DER P", der_s.real), ("DER Q", der_s.imag), ("load scale", scale)):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{net.name}: {label} contains NaN or inf")
    if der_s.ndim and der_s.shape[-1] not in (len(net.ders), 1):
        raise InputError(f"{net.name}: {der_s.shape[-1]} DER values given for {len(net.ders)} DER units")
    if np.any(scale < 0):
        raise InputError(f"{net.name}: load scale must be non-negative, got {scale.min()}")
    der_s = np.broadcast_to(der_s, der_s.shape[:-1] + (len(net.ders),)) if der_s.ndim else np.full(len(net.ders), der_s)
    fixed = np.zeros(net.n_bus, dtype=complex)
    np.add.at(fixed, net.gen_bus, net.gen_p_mw + 1j * net.gen_q_mvar)
    if bus_load_mva is None:
        load = net.load_p_mw + 1j * net.load_q_mvar
        base = fixed - scale[..., None] * load
    else:
        bus_load = np.asarray(bus_load_mva, dtype=complex)
        if bus_load.shape[-1] != net.n_bus or not np.all(np.isfinite(bus_load)):
            raise InputError(f"{net.name}: bus loads must be finite, shaped (..., {net.n_bus}), got {bus_load.shape}")
        base = fixed - bus_load
    lead = np.broadcast_shapes(base.shape[:-1], der_s.shape[:-1])
    out = np.broadcast_to(base, lead + (net.n_bus,)).copy()
    np.add.at(out.T, net.der_bus, np.broadcast_to(der_s, lead + der_s.shape[-1:]).T)  # bus axis first
    return out


def check_injections(net: Network, s_mw: np.ndarray) -> np.ndarray:
    """`s_mw` as a complex array, after checking its bus count and finiteness."""
    s_mw = np.asarray(s_mw, dtype=complex)
    if s_mw.shape[-1] != net.n_bus:
        raise InputError(f"{net.name}: injections have {s_mw.shape[-1]} buses, the network has {net.n_bus}")
    if not np.all(np.isfinite(s_mw)):
        raise InputError(f"{net.name}: bus injections contain NaN or inf")
    return s_mw


def flat_start(net: Network) -> np.ndarray:
    """1 p.u. everywhere, PV buses at their setpoint, the slack at its voltage (a new array)."""
    return _flat(net).copy()


@lru_cache(maxsize=16)
def _flat(net: Network) -> np.ndarray:
    v = np.ones(net.n_bus, dtype=complex)
    at_pv = np.isin(net.gen_bus, net.pv_buses)
    v[net.gen_bus[at_pv]] = net.gen_vset[at_pv]
    v[net.slack] = net.v_slack
    v.setflags(write=False)
    return v


def bus_types(net: Network) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pv, pq, pvpq) internal bus indices: PV buses, PQ buses, and both (PV first)."""
    pv = net.pv_buses
    pq = np.setdiff1d(np.flatnonzero(net.bus_type != 3), pv)
    return pv, pq, np.concatenate([pv, pq])
