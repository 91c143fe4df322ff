"""AC power flow: Newton–Raphson in polar form (one snapshot) and a batched solver
(many snapshots at once, arrays shaped snapshots × buses).

Inputs are net complex bus injections in MW/MVAr (generation minus load, positive =
into the grid); `bus_injections` builds them from loads, DER setpoints and the case's
fixed generators. Results carry complex bus voltages (p.u.), branch flows at both ends
(MW/MVAr, positive = leaving the bus into the branch) and total losses (kW).

The batched solver is the implicit Z-bus (current-injection fixed-point) method:
V = V₀ + Z·conj(S/V) with Z = Y_red⁻¹ factored once per network. On a radial feeder this
is the matrix form of the backward/forward sweep; it works unchanged on meshed feeders.
Every snapshot is iterated as one column of a matrix. Snapshots it cannot converge (or
networks with PV buses) are handed to Newton–Raphson, one by one, and flagged exactly as
NR reports.

Dense or sparse: feeders below `SPARSE_MIN_BUSES` buses use dense kernels (`dense`: a
dense Jacobian, Z as an explicit inverse, one mat-mul per step); larger ones sparse
kernels (`sparse`: SuperLU factors of the sparse Jacobian and of Y_red, memory linear in
the bus count). Both give the same answers to the solver tolerances.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from opfbench.network import Network
from opfbench.powerflow.common import (
    MAX_NR_ITER,
    MAX_SWEEP_ITER,
    MISMATCH_CHECK,
    NR_TOLERANCE,
    SPARSE_MIN_BUSES,
    SWEEP_TOLERANCE,
    PowerFlowResult,
    bus_injections,
    check_injections,
    flat_start,
    uses_sparse,
)
from opfbench.powerflow.dense import DenseNewton, DenseZbus
from opfbench.powerflow.fixed_point import fixed_point, max_mismatch
from opfbench.powerflow.memo import first_rows, flow_memo, row_digests, same_snapshots, snapshot_words
from opfbench.powerflow.sparse import SparseNewton, SparseZbus
from opfbench.state import PROCESS
from opfbench.threads import one_blas_thread

__all__ = [
    "MAX_NR_ITER",
    "MAX_SWEEP_ITER",
    "MISMATCH_CHECK",
    "NR_TOLERANCE",
    "SPARSE_MIN_BUSES",
    "SWEEP_TOLERANCE",
    "PowerFlowResult",
    "bus_injections",
    "solve_pf",
    "solve_pf_batch",
    "uses_sparse",
]


@lru_cache(maxsize=16)
def _newton(net: Network, sparse: bool) -> DenseNewton | SparseNewton:
    return SparseNewton(net) if sparse else DenseNewton(net)


def solve_pf(
    net: Network,
    s_mw: np.ndarray,
    v0: np.ndarray | None = None,
    tol: float = NR_TOLERANCE,
    max_iter: int = MAX_NR_ITER,
    sparse: bool | None = None,
) -> PowerFlowResult:
    """Newton–Raphson, polar coordinates; dense Jacobian below SPARSE_MIN_BUSES buses,
    sparse (SuperLU) from there on, or as `sparse` forces.

    `s_mw`: net bus injections (n_bus,) complex MW; `v0` an optional start (warm start).
    Converged when the largest P/Q mismatch is below `tol` p.u. Non-convergence
    (divergence, singular Jacobian, iteration limit) returns `converged=False`; it never
    raises.
    """
    s = check_injections(net, s_mw) / net.base_mva
    system = _newton(net, uses_sparse(net) if sparse is None else sparse)
    v = flat_start(net) if v0 is None else np.array(v0, dtype=complex)
    v[net.slack] = net.v_slack * np.exp(1j * np.angle(v[net.slack]))
    s_sub = s[system.pvpq]
    n = len(system.pvpq)
    it = 0
    with np.errstate(all="ignore"):  # a diverging iterate overflows; it is caught as non-finite below
        f = system.mismatch(v, s_sub)
        converged = bool(np.max(np.abs(f), initial=0.0) < tol)
        while not converged and it < max_iter:
            it += 1
            dx = system.step(v, f)
            if dx is None:
                break
            va, vm = np.angle(v), np.abs(v)
            va[system.pvpq] += dx[:n]
            vm[system.pq] += dx[n:]
            v = vm * np.exp(1j * va)
            f = system.mismatch(v, s_sub)
            if not np.all(np.isfinite(f)):
                break
            converged = bool(np.max(np.abs(f)) < tol)
    return PowerFlowResult(net, v, np.asarray(converged), np.asarray(it, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class _ZbusFactor:
    """Per-network data for the batched fixed-point solver."""

    keep: np.ndarray  # non-slack bus indices
    z: DenseZbus | SparseZbus  # applies Y[keep, keep]⁻¹
    v_noload: np.ndarray  # -Z·Y[keep, slack]·V_slack
    v_noload_full: np.ndarray  # (n_bus,) no-load voltages including the slack
    y_rows: sp.csr_matrix  # Y[keep, :], for the mismatch check


@lru_cache(maxsize=16)
def _zbus(net: Network, sparse: bool) -> _ZbusFactor:
    keep = np.flatnonzero(np.arange(net.n_bus) != net.slack)
    z = SparseZbus(net, keep) if sparse else DenseZbus(net, keep)
    y_slack = net.ybus_sparse[:, [net.slack]].toarray()[keep]  # (m, 1)
    v_noload = np.empty((len(keep), 1), dtype=complex)
    z.apply(-y_slack * net.v_slack, v_noload)
    full = np.full(net.n_bus, net.v_slack, dtype=complex)
    full[keep] = v_noload[:, 0]
    return _ZbusFactor(keep, z, v_noload[:, 0], full, net.ybus_sparse[keep])


def _forget_factors() -> None:
    _newton.cache_clear()
    _zbus.cache_clear()


PROCESS.on_reset("power-flow factorizations", _forget_factors)


def solve_pf_batch(
    net: Network,
    s_mw: np.ndarray,
    v0: np.ndarray | None = None,
    tol: float = SWEEP_TOLERANCE,
    max_iter: int = MAX_SWEEP_ITER,
    sparse: bool | None = None,
) -> PowerFlowResult:
    """Power flow for many snapshots at once; `s_mw` shaped (S, n_bus) complex MW; `v0`
    (S, n_bus) complex p.u. an optional warm start (e.g. the previous solution of a
    nearby operating point; non-finite rows fall back to the no-load start). Dense
    kernels below SPARSE_MIN_BUSES buses, sparse from there on, or as `sparse` forces.

    Returns a result with arrays shaped (S, n_bus) and per-snapshot `converged` and
    `iterations`. A snapshot counts as solved when its fixed-point update is below `tol`
    p.u. *and* its P/Q mismatch is below `MISMATCH_CHECK` p.u.; the others (and every
    snapshot of a network with PV buses) are solved by Newton–Raphson individually and
    carry NR's verdict and iteration count. A snapshot this thread solved recently from the
    same injections and start (or none) is not solved again (`memo.FlowMemo`).
    """
    sparse = uses_sparse(net) if sparse is None else sparse
    s = np.ascontiguousarray(check_injections(net, np.atleast_2d(s_mw)) / net.base_mva, dtype=complex)
    v0 = None if v0 is None else np.ascontiguousarray(np.asarray(v0, dtype=complex).reshape(s.shape))
    return _remembered(net, s, v0, (tol, max_iter, sparse))


def _remembered(net: Network, s: np.ndarray, v0: np.ndarray | None, options: tuple[float, int, bool]) -> PowerFlowResult:
    """`_batch` on the snapshots of `s` (and `v0`) this thread has not solved recently (each
    distinct one once: rows of one digest are one snapshot only where their bytes agree);
    the others' answers from `memo.FlowMemo`."""
    memo = flow_memo()
    digests = row_digests(s, v0)
    known, v, converged, iterations = memo.find(net, options, digests, s, v0)
    new = np.flatnonzero(~known)
    earlier = new[first_rows(digests[new])]  # the first row of `new` with each one's digest
    twin = earlier != new  # the same snapshot again, unless another one that shares its digest
    if new.size == digests.size and not twin.any():  # every snapshot new, each once
        result = _batch(net, s, v0, *options)
        memo.put(net, options, digests, s, None if v0 is None else v0.copy(), result)  # `s` is this call's own
        return result
    if not new.size:
        return PowerFlowResult(net, v, converged, iterations)
    words = snapshot_words(s, v0)
    same = np.zeros(new.size, dtype=bool)
    same[twin] = same_snapshots(words, new[twin], words, earlier[twin])
    rows = new[~same]
    s_new, v0_new = s[rows], None if v0 is None else v0[rows]
    solved = _batch(net, s_new, v0_new, *options)
    memo.put(net, options, digests[rows], s_new, v0_new, solved)
    taken = np.searchsorted(rows, np.where(same, earlier, new))
    v[new], converged[new], iterations[new] = solved.v[taken], solved.converged[taken], solved.iterations[taken]
    return PowerFlowResult(net, v, converged, iterations)


def _batch(net: Network, s: np.ndarray, v0: np.ndarray | None, tol: float, max_iter: int, sparse: bool) -> PowerFlowResult:
    """`solve_pf_batch` on injections `s` (S, n_bus) p.u."""
    n_snap = s.shape[0]
    if net.pv_buses.size:
        results = [solve_pf(net, row * net.base_mva, sparse=sparse) for row in s]
        return PowerFlowResult(
            net,
            np.array([r.v for r in results]),
            np.array([r.converged for r in results]),
            np.array([r.iterations for r in results]),
        )
    fac = _zbus(net, sparse)
    v = np.empty((n_snap, net.n_bus), dtype=complex)
    v[:, net.slack] = net.v_slack
    with one_blas_thread():
        start = None
        if v0 is not None:
            v0 = np.asarray(v0, dtype=complex).reshape(n_snap, net.n_bus)
            usable = np.isfinite(v0).all(axis=1, keepdims=True) & (np.abs(v0) > 0).all(axis=1, keepdims=True)
            start = np.where(usable, v0, fac.v_noload_full)
        sweep = fixed_point(fac.z, fac.keep, fac.v_noload, s, tol, max_iter, start, v)
    # Certify: the power-flow equations themselves must hold, not only the fixed point.
    mismatch = max_mismatch(v, s, fac.keep, fac.y_rows)
    iterations, settled = sweep.iterations, sweep.settled
    settled &= mismatch < MISMATCH_CHECK
    converged = settled.copy()
    for k in np.flatnonzero(~settled):
        r = solve_pf(net, s[k] * net.base_mva, sparse=sparse)
        v[k], converged[k], iterations[k] = r.v, r.converged, r.iterations
    return PowerFlowResult(net, v, converged, iterations)
