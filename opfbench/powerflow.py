"""AC power flow: Newton–Raphson in polar form (one snapshot) and a batched solver
(many snapshots at once, arrays shaped snapshots × buses).

Inputs are net complex bus injections in MW/MVAr (generation minus load, positive =
into the grid); `bus_injections` builds them from loads, DER setpoints and the case's
fixed generators. Results carry complex bus voltages (p.u.), branch flows at both ends
(MW/MVAr, positive = leaving the bus into the branch) and total losses (kW).

The batched solver is the implicit Z-bus (current-injection fixed-point) method:
V = V₀ + Z·conj(S/V) with Z = Y_red⁻¹ factored once per network. On a radial feeder this
is the matrix form of the backward/forward sweep; it works unchanged on meshed feeders.
Every snapshot is iterated as one column of a matrix, so the work is a few dense
mat-muls for the whole batch. Snapshots it cannot converge (or networks with PV
buses) are handed to Newton–Raphson, one by one, and flagged exactly as NR reports.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from threadpoolctl import ThreadpoolController

from opfbench.errors import InputError
from opfbench.network import Network

NR_TOLERANCE = 1e-9  # p.u. largest P/Q mismatch (Newton–Raphson)
SWEEP_TOLERANCE = 1e-10  # p.u. largest voltage update (batched fixed point)
MISMATCH_CHECK = 1e-8  # p.u.; a batched snapshot whose mismatch exceeds this goes to NR
MAX_NR_ITER = 30
MAX_SWEEP_ITER = 200
# The batched mat-muls are small (n_bus² × S); multi-threaded BLAS only adds
# synchronisation there, and is many times slower when the other core is busy.
_BLAS = ThreadpoolController()


@dataclass(frozen=True, eq=False)
class PowerFlowResult:
    """Solution of one snapshot (arrays shaped (n_bus,)) or of a batch ((S, n_bus))."""

    net: Network
    v: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray

    @property
    def vm(self) -> np.ndarray:
        return np.abs(self.v)

    @property
    def va_deg(self) -> np.ndarray:
        return np.rad2deg(np.angle(self.v))

    @cached_property
    def _flows(self) -> tuple[np.ndarray, np.ndarray]:
        yff, yft, ytf, ytt = self.net.branch_admittances
        vf, vt = self.v[..., self.net.f], self.v[..., self.net.t]
        base = self.net.base_mva
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

    @property
    def losses_kw(self) -> np.ndarray:
        """Total series + charging active losses over all branches (kW)."""
        sf, st = self._flows
        return (sf + st).real.sum(axis=-1) * 1e3

    @property
    def slack_s_mva(self) -> np.ndarray:
        """Complex power injected by the slack bus into the grid (MW + jMVAr)."""
        s = self.net.slack
        return self.v[..., s] * np.conj(self.v @ self.net.ybus[s]) * self.net.base_mva

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
) -> np.ndarray:
    """Net complex injection per bus (MW + jMVAr): fixed gens + DER − load_scale·load.

    `der_p_mw`/`der_q_mvar` are shaped (n_der,) or (S, n_der); `load_scale` is a scalar
    or (S,). Returns (n_bus,) or (S, n_bus).
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
    load = net.load_p_mw + 1j * net.load_q_mvar
    fixed = np.zeros(net.n_bus, dtype=complex)
    np.add.at(fixed, net.gen_bus, net.gen_p_mw + 1j * net.gen_q_mvar)
    base = fixed - scale[..., None] * load
    lead = np.broadcast_shapes(base.shape[:-1], der_s.shape[:-1])
    out = np.broadcast_to(base, lead + (net.n_bus,)).copy()
    np.add.at(out, (..., net.der_bus), np.broadcast_to(der_s, lead + der_s.shape[-1:]))
    return out


def _check_injections(net: Network, s_mw: np.ndarray) -> np.ndarray:
    s_mw = np.asarray(s_mw, dtype=complex)
    if s_mw.shape[-1] != net.n_bus:
        raise InputError(f"{net.name}: injections have {s_mw.shape[-1]} buses, the network has {net.n_bus}")
    if not np.all(np.isfinite(s_mw)):
        raise InputError(f"{net.name}: bus injections contain NaN or inf")
    return s_mw


def _flat_start(net: Network) -> np.ndarray:
    v = np.ones(net.n_bus, dtype=complex)
    at_pv = np.isin(net.gen_bus, net.pv_buses)
    v[net.gen_bus[at_pv]] = net.gen_vset[at_pv]
    v[net.slack] = net.v_slack
    return v


@dataclass(frozen=True, eq=False)
class _NewtonIndex:
    """Per-network index sets and admittance blocks for Newton–Raphson."""

    pv: np.ndarray
    pq: np.ndarray
    pvpq: np.ndarray
    y_rows: np.ndarray  # Y[pvpq, :]
    y_sub: np.ndarray  # Y[pvpq][:, pvpq]


@lru_cache(maxsize=64)
def _newton_index(net: Network) -> _NewtonIndex:
    pv = net.pv_buses
    pq = np.setdiff1d(np.flatnonzero(net.bus_type != 3), pv)
    pvpq = np.concatenate([pv, pq])
    return _NewtonIndex(pv, pq, pvpq, net.ybus[pvpq], net.ybus[np.ix_(pvpq, pvpq)])


def solve_pf(net: Network, s_mw: np.ndarray, v0: np.ndarray | None = None,
             tol: float = NR_TOLERANCE, max_iter: int = MAX_NR_ITER) -> PowerFlowResult:
    """Newton–Raphson, polar coordinates, dense Jacobian (distribution feeders are small).

    `s_mw`: net bus injections (n_bus,) complex MW; `v0` an optional start (warm start).
    Converged when the largest P/Q mismatch is below `tol` p.u. Non-convergence
    (divergence, singular Jacobian, iteration limit) returns `converged=False`; it never
    raises.
    """
    s = _check_injections(net, s_mw) / net.base_mva
    idx = _newton_index(net)
    n_pv, n = len(idx.pv), len(idx.pvpq)
    rows = np.arange(n)
    pos_pv = rows  # position of each pvpq bus inside the pvpq ordering
    v = _flat_start(net) if v0 is None else np.array(v0, dtype=complex)
    v[net.slack] = net.v_slack * np.exp(1j * np.angle(v[net.slack]))
    s_sub = s[idx.pvpq]
    jac = np.empty((n + len(idx.pq), n + len(idx.pq)))

    def mismatch(v: np.ndarray) -> np.ndarray:
        mis = v[idx.pvpq] * np.conj(idx.y_rows @ v) - s_sub
        return np.concatenate([mis.real, mis.imag[n_pv:]])

    f = mismatch(v)
    converged = bool(np.max(np.abs(f)) < tol)
    it = 0
    while not converged and it < max_iter:
        it += 1
        vs = v[idx.pvpq]
        ibus = idx.y_rows @ v
        vnorm = vs / np.abs(vs)
        # dS/dVa and dS/dVm restricted to rows and columns pvpq (MATPOWER dSbus_dV).
        vy = vs[:, None] * np.conj(idx.y_sub)
        ds_dva = -1j * vy * np.conj(vs)
        ds_dva[rows, pos_pv] += 1j * vs * np.conj(ibus)
        ds_dvm = vy * np.conj(vnorm)
        ds_dvm[rows, pos_pv] += np.conj(ibus) * vnorm
        jac[:n, :n] = ds_dva.real
        jac[:n, n:] = ds_dvm[:, n_pv:].real
        jac[n:, :n] = ds_dva[n_pv:].imag
        jac[n:, n:] = ds_dvm[n_pv:, n_pv:].imag
        try:
            dx = np.linalg.solve(jac, -f)
        except np.linalg.LinAlgError:
            break
        va, vm = np.angle(v), np.abs(v)
        va[idx.pvpq] += dx[:n]
        vm[idx.pq] += dx[n:]
        v = vm * np.exp(1j * va)
        f = mismatch(v)
        if not np.all(np.isfinite(f)):
            break
        converged = bool(np.max(np.abs(f)) < tol)
    return PowerFlowResult(net, v, np.bool_(converged), np.int64(it))


@dataclass(frozen=True, eq=False)
class _ZbusFactor:
    """Per-network data for the batched fixed-point solver."""

    keep: np.ndarray  # non-slack bus indices
    z: np.ndarray  # inverse of Y[keep, keep]
    v_noload: np.ndarray  # -Z·Y[keep, slack]·V_slack
    y_keep_t: np.ndarray  # Y[keep, :].T, for the final mismatch check
    v_noload_full: np.ndarray  # (n_bus,) no-load voltages including the slack


@lru_cache(maxsize=64)
def _zbus(net: Network) -> _ZbusFactor:
    keep = np.flatnonzero(np.arange(net.n_bus) != net.slack)
    y = net.ybus
    z = np.linalg.inv(y[np.ix_(keep, keep)])
    v_noload = -z @ y[keep, net.slack] * net.v_slack
    full = np.full(net.n_bus, net.v_slack, dtype=complex)
    full[keep] = v_noload
    return _ZbusFactor(keep, z, v_noload, np.ascontiguousarray(y[keep].T), full)


@dataclass
class _Sweep:
    v: np.ndarray  # (m, S) complex voltages of the non-slack buses
    iterations: np.ndarray  # (S,)
    settled: np.ndarray  # (S,) bool: update fell below tol


def _fixed_point(fac: _ZbusFactor, s_conj: np.ndarray, tol: float, max_iter: int,
                 v_start: np.ndarray | None) -> _Sweep:
    """Iterate V ← Z·conj(S/V) + V₀ on all columns of `s_conj` (conj(S), shape (m, S)),
    starting from `v_start` (m, S) or, without it, from the no-load voltages.

    Written with preallocated buffers and in-place ufuncs: at 1440 snapshots the
    temporaries of the plain expression cost more than the mat-mul itself.
    """
    m, n_snap = s_conj.shape
    start = np.repeat(fac.v_noload[:, None], n_snap, axis=1) if v_start is None else v_start.astype(complex)
    out = _Sweep(start,
                 np.zeros(n_snap, dtype=np.int64), np.zeros(n_snap, dtype=bool))
    active = np.arange(n_snap)
    v, s_act = out.v.copy(), s_conj
    v_new, cur = np.empty_like(v), np.empty_like(v)
    mag2, tmp = np.empty(v.shape), np.empty(v.shape)
    v0 = fac.v_noload[:, None]
    with np.errstate(all="ignore"):
        for it in range(1, max_iter + 1):
            np.square(v.real, out=mag2)
            np.square(v.imag, out=tmp)
            mag2 += tmp
            np.reciprocal(mag2, out=mag2)
            np.multiply(s_act, v, out=cur)
            cur *= mag2  # conj(S/V) = conj(S)·V/|V|²
            np.matmul(fac.z, cur, out=v_new)
            v_new += v0
            np.subtract(v_new, v, out=cur)
            np.square(cur.real, out=mag2)
            np.square(cur.imag, out=tmp)
            mag2 += tmp
            step2 = mag2.max(axis=0)
            v, v_new = v_new, v
            out.iterations[active] = it
            done = step2 < tol * tol
            going = ~done & np.isfinite(step2)
            if going.all():
                continue
            out.v[:, active] = v
            out.settled[active[done]] = True
            if not going.any():
                return out
            active, v, s_act = active[going], v[:, going], s_act[:, going]
            v_new, cur = np.empty_like(v), np.empty_like(v)
            mag2, tmp = np.empty(v.shape), np.empty(v.shape)
    out.v[:, active] = v
    return out


def solve_pf_batch(net: Network, s_mw: np.ndarray, v0: np.ndarray | None = None,
                   tol: float = SWEEP_TOLERANCE, max_iter: int = MAX_SWEEP_ITER) -> PowerFlowResult:
    """Power flow for many snapshots at once; `s_mw` shaped (S, n_bus) complex MW; `v0`
    (S, n_bus) complex p.u. an optional warm start (e.g. the previous solution of a
    nearby operating point; non-finite rows fall back to the no-load start).

    Returns a result with arrays shaped (S, n_bus) and per-snapshot `converged` and
    `iterations`. A snapshot counts as solved when its fixed-point update is below `tol`
    p.u. *and* its P/Q mismatch is below `MISMATCH_CHECK` p.u.; the others (and every
    snapshot of a network with PV buses) are solved by Newton–Raphson individually and
    carry NR's verdict and iteration count.
    """
    s = _check_injections(net, np.atleast_2d(s_mw)) / net.base_mva
    n_snap = s.shape[0]
    if net.pv_buses.size:
        results = [solve_pf(net, row * net.base_mva) for row in s]
        return PowerFlowResult(net, np.array([r.v for r in results]),
                               np.array([r.converged for r in results]), np.array([r.iterations for r in results]))
    fac = _zbus(net)
    with _BLAS.limit(limits=1, user_api="blas"):
        start = None
        if v0 is not None:
            v0 = np.asarray(v0, dtype=complex).reshape(n_snap, net.n_bus)
            start = np.where(np.isfinite(v0).all(axis=1, keepdims=True) & (np.abs(v0) > 0).all(axis=1, keepdims=True),
                             v0, fac.v_noload_full)[:, fac.keep].T.copy()
        sweep = _fixed_point(fac, np.conj(s[:, fac.keep]).T, tol, max_iter, start)
        v = np.empty((n_snap, net.n_bus), dtype=complex)
        v[:, fac.keep] = sweep.v.T
        v[:, net.slack] = net.v_slack
        # Certify: the power-flow equations themselves must hold, not only the fixed point.
        with np.errstate(all="ignore"):
            mismatch = np.abs(v[:, fac.keep] * np.conj(v @ fac.y_keep_t) - s[:, fac.keep]).max(axis=1)
    iterations, settled = sweep.iterations, sweep.settled
    settled &= mismatch < MISMATCH_CHECK
    converged = settled.copy()
    for k in np.flatnonzero(~settled):
        r = solve_pf(net, s[k] * net.base_mva)
        v[k], converged[k], iterations[k] = r.v, r.converged, r.iterations
    return PowerFlowResult(net, v, converged, iterations)
