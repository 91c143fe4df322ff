"""The batched three-phase power flow on a `PhaseNetwork`: OpenDSS's own "normal"
current-injection iteration, on S snapshots at once.

The network equations at node level are

    Y·V = I_source + I_branches(V),

Y the elements' and the source's admittances, I_source the source's Norton current, and
I_branches the currents the load branches draw (their OpenDSS models,
`opfbench.multiphase.branches`) and the DER branches inject (constant power). As OpenDSS
does, the loads' nominal admittances Y_L go into the factored matrix and the iteration is

    V ← A⁻¹·(I_source + I_branches(V) + Y_L·V),    A = Y + Y_L,

A factored once per network (SuperLU) and reused across snapshots and iterations (a
constant-impedance load is exact in one step). Only the nodes the branches touch (K)
enter the iteration; with few of them (`DENSE_MAX_NODES`, `DENSE_MAX_ENTRIES`) the
impedances Z_NK = (A⁻¹)_{:,K} are formed once, an iteration is one small dense product
Z_KK·J on all snapshots' columns, and every node follows from one product Z_NK·J at the
end; with many the iteration solves with the sparse factor on every node.

With `PhaseNetwork.tap_control` (the case's `?taps=control`) the solve is the inner loop
of OpenDSS's control loop: solve every snapshot at its regulators' tap positions, let the
regulators sample and move (`opfbench.multiphase.regulators`), solve again, until no
regulator is armed in the snapshot (at most `MAX_CONTROL_ITER` rounds; one that is still
armed then has not converged). Snapshots at equal positions share one factorization.

A snapshot has converged when its largest node-voltage update is below `tol` p.u. of the
node's base voltage and the equations hold at the result: at every node the current
mismatch |Y·V − I_source − I_branches(V)| is below `MISMATCH_REL` of the currents that
meet there (`_residual`). One that has not after `max_iter` iterations is reported not
converged (its voltages are no operating point and carry no figure). Dense, the mismatch
is formed per snapshot on K alone: at every other node Y equals A, so the mismatch there
of V = A⁻¹·I_source + Z_NK·J is, for every J, the residual of the solves that formed
A⁻¹·I_source and Z_NK — certified once per network (`_linear_error`) and part of every
snapshot's mismatch.

The two halves are separate calls: `iterate_phase_flow` runs the iteration and keeps a
`PhaseIterate` (the currents J on K when dense, every node's voltage when sparse), from
which every node's voltage follows on demand; `certify` forms every node's voltage, the
mismatch and the losses. `solve_phase_flow` is the two in one. A closed loop answering
many setpoints (`opfbench.strategies.grids.PhaseGrid`) iterates and certifies only the
flow that gives its figures.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from typing import Any, Self

import numpy as np
import scipy.sparse as sp
from numba import njit

from opfbench.errors import InputError
from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.multiphase.branches import BranchLaw, branch_currents
from opfbench.multiphase.regulators import ControlState, act, control_voltage, sample
from opfbench.powerflow.common import MAX_SWEEP_ITER, SWEEP_TOLERANCE
from opfbench.powerflow.sparse import factorize
from opfbench.threads import one_blas_thread

DENSE_MAX_NODES = 800
"""Iterate on the reduced dense impedance when at most this many nodes carry branches…"""
DENSE_MAX_ENTRIES = 2**22
"""… and the impedances from them to every node (n_node × that many, complex) take at most
this many entries (64 MB)."""
MISMATCH_REL = 1e-8
"""The largest relative nodal current mismatch a converged snapshot may have (`_residual`)."""
MAX_CONTROL_ITER = 100
"""Rounds of solve-and-move a snapshot's regulators get to settle (`taps=control`)."""
_CHUNK = 256  # columns per sparse solve when forming Z_KK (memory: n_node × _CHUNK)
_BLOCK_BYTES = 2**22  # node voltages per block when certifying every node (`_certify_every_node`): 4 MB
_ROUND_OFF_PU = 1e-12  # far above the round-off between two ways of forming a node's |V| (p.u.)


@dataclass(frozen=True, eq=False)
class PhaseFlowResult:
    """Node voltages `v` (S, n_node) complex V of S snapshots, `converged` (S,) bool,
    `iterations` (S,), `mismatch` (S,) the largest relative nodal current mismatch at the
    result (`_residual`), `tap_positions` (S, n_regulator) where the regulators settled
    (`taps=control`; indices into `Regulator.taps`, else None), `losses_kw` (S,)
    active losses in the power-delivery elements (the source's Thevenin impedance
    excluded, as OpenDSS's circuit losses): the power the source delivers minus what the
    branches draw — free of the round-off that summing V·conj(Y·V) over near-zero-impedance
    switches carries."""

    net: PhaseNetwork
    v: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    mismatch: np.ndarray
    losses_kw: np.ndarray
    tap_positions: np.ndarray | None = None

    @property
    def n_snapshots(self) -> int:
        return self.v.shape[0]

    def with_converged(self, converged: np.ndarray) -> Self:
        """The same voltages with the verdict `converged` (S,) (e.g. a strategy's own: a
        snapshot one of whose earlier flows diverged)."""
        return replace(self, converged=np.asarray(converged, dtype=bool))

    @cached_property
    def node_vm_pu(self) -> np.ndarray:
        """(S, n_node) |V| in p.u. of each node's phase-to-neutral base (OpenDSS's node p.u.)."""
        return np.abs(self.v) / self.net.node_base_v

    @cached_property
    def vm(self) -> np.ndarray:
        """(S, n_monitored) the voltages the band applies to, p.u. (`PhaseNetwork.monitored`)."""
        a, b, base, _ = self.net.monitored
        return _magnitude_across(self.v, a, b) / base

    @cached_property
    def der_vm(self) -> np.ndarray:
        """(S, n_der) the voltage each DER measures, p.u.: its branches' voltages (phase to
        neutral, or phase to phase for a delta unit) in p.u. of their bases, averaged over
        its phases (`PhaseNetwork.der_measure`)."""
        db = self.net.der_branches
        return _measured(self.net, _magnitude_across(self.v, db.a, db.b))

    @cached_property
    def source_kva(self) -> np.ndarray:
        """(S,) complex power the source delivers into its bus (kW + j kvar)."""
        return _source_kva(self.net, self.v.T)

    @cached_property
    def vuf(self) -> np.ndarray:
        """(S, n_three_phase_buses) voltage unbalance factor |V₂|/|V₁| at the buses with
        phases 1, 2, 3 (`PhaseNetwork.three_phase_nodes`), from the phase voltages."""
        nodes = self.net.three_phase_nodes
        a = np.exp(2j * np.pi / 3)
        va, vb, vc = (self.v[:, nodes[:, k]] for k in range(3))
        v1 = (va + a * vb + a * a * vc) / 3
        v2 = (va + a * a * vb + a * vc) / 3
        with np.errstate(all="ignore"):
            return np.abs(v2) / np.abs(v1)


@dataclass(frozen=True, eq=False)
class _System:
    """Per-network data of the iteration (built once, `_system`)."""

    k: np.ndarray  # nodes the branches touch
    lu: Any  # scipy's SuperLU of A = Y + Y_L
    v_source: np.ndarray  # (n_node,) A⁻¹·I_source
    y_load_kk: sp.csr_matrix  # (m, m) Y_L on K
    z_nk: np.ndarray | None  # (n_node, m) (A⁻¹)_{:,K} when dense
    z_kk: np.ndarray | None  # (m, m) its rows K
    load_a: np.ndarray  # load branch ends, positions in K (m = ground)
    load_b: np.ndarray
    der_a: np.ndarray
    der_b: np.ndarray
    vbase_load: np.ndarray  # (n_load_branch,) the load branches' base voltages
    base_k: np.ndarray  # (m, 1) node base voltages on K
    law: BranchLaw  # the load branches' current law
    ybus_abs: sp.csc_matrix  # |Y| entrywise (the residual's scale)
    near: np.ndarray  # K and the nodes Y joins to K: what the residual on K reads
    y_k_near: sp.csr_matrix  # (m, len(near)) Y's rows K on those nodes
    linear_error: float  # dense: the solves' backward error (`_linear_error`), every other node's mismatch

    def injections(self, v_k: np.ndarray, p_br: np.ndarray, q_br: np.ndarray, s_der: np.ndarray) -> np.ndarray:
        """(m, S') branch currents injected into the nodes K at their voltages v_k (m, S'),
        for the branch powers of those S' snapshots (`_branch_powers`)."""
        return self._currents(v_k, p_br, q_br, s_der, _NO_ROWS)

    def iteration_currents(self, v_k: np.ndarray, p_br: np.ndarray, q_br: np.ndarray, s_der: np.ndarray) -> np.ndarray:
        """(m, S') the currents J the iteration injects at K: the branches' (`injections`)
        and the load admittances' Y_L·V."""
        return self._currents(v_k, p_br, q_br, s_der, self.y_load_kk)

    def _currents(self, v_k, p_br, q_br, s_der, y: sp.csr_matrix) -> np.ndarray:
        out = np.empty(v_k.shape, dtype=complex)
        branch_currents(
            np.ascontiguousarray(v_k),
            (
                self.load_a,
                self.load_b,
                np.ascontiguousarray(p_br),
                np.ascontiguousarray(q_br),
                self.vbase_load,
                *self.law.constants,
            ),
            (self.der_a, self.der_b, np.ascontiguousarray(s_der)),
            (y.indptr if y.shape[0] else np.zeros(len(v_k) + 1, dtype=y.indptr.dtype), y.indices, y.data),
            out,
        )
        return out


_NO_ROWS = sp.csr_matrix((0, 0), dtype=complex)


@lru_cache(maxsize=8)
def _system(net: PhaseNetwork) -> _System:
    lb, db = net.load_branches, net.der_branches
    ends = [lb.a, lb.b[lb.b != GROUND], db.a, db.b[db.b != GROUND]]
    k = np.unique(np.concatenate(ends)) if any(e.size for e in ends) else np.zeros(0, dtype=int)
    m = len(k)
    pos = np.full(net.n_node, m)
    pos[k] = np.arange(m)
    pos_g = np.append(pos, m)  # GROUND (−1) → the zero row m
    y_rows = net.ybus.tocsr()[k]
    near = np.union1d(k, y_rows.indices).astype(np.int64)

    y_load = _load_admittance(net)
    lu = factorize(net.ybus + y_load)
    v_source = lu.solve(np.asarray(net.source_current, dtype=complex))
    z_nk = None
    if 0 < m <= DENSE_MAX_NODES and net.n_node * m <= DENSE_MAX_ENTRIES:
        z_nk = np.empty((net.n_node, m), dtype=complex)
        for start in range(0, m, _CHUNK):
            cols = k[start : start + _CHUNK]
            rhs = np.zeros((net.n_node, len(cols)), dtype=complex, order="F")
            rhs[cols, np.arange(len(cols))] = 1.0
            z_nk[:, start : start + len(cols)] = lu.solve(rhs)
    return _System(
        k,
        lu,
        v_source,
        y_load[k][:, k].tocsr(),
        z_nk,
        None if z_nk is None else np.ascontiguousarray(z_nk[k]),
        pos_g[lb.a],
        pos_g[lb.b],
        pos_g[db.a],
        pos_g[db.b],
        np.ascontiguousarray(lb.vbase_v),
        net.node_base_v[k][:, None],
        net.load_models.branch_law(lb.owner),
        abs(net.ybus).tocsc(),
        near,
        y_rows[:, near].tocsr(),
        np.inf if z_nk is None else _linear_error(net, v_source, z_nk, k),
    )


def _load_admittance(net: PhaseNetwork) -> sp.csc_matrix:
    """(n_node, n_node) Y_L: the load branches' nominal admittances (module docstring)."""
    lb = net.load_branches
    y_branch = (net.load_p_mw[lb.owner] - 1j * net.load_q_mvar[lb.owner]) * 1e6 * lb.share / lb.vbase_v**2
    c_load = lb.incidence(net.n_node)
    return (c_load @ sp.diags(y_branch) @ c_load.T).tocsc()


def _linear_error(net: PhaseNetwork, v_source: np.ndarray, z_nk: np.ndarray, k: np.ndarray) -> float:
    """The componentwise backward error of the solves every node's voltage is formed
    from: max |A·x − e| / (|A|·|x| + |e|) over the columns x = A⁻¹·I_source (e = I_source)
    and x = (A⁻¹)_{:,k} (e the unit vector at k), at every node. Where no branch is (N∖K)
    Y equals A there, so the nodal mismatch of V = A⁻¹·I_source + Z_NK·J is, for any J,
    the combination of these columns' residuals there: it is certified once per network."""
    a = net.ybus + _load_admittance(net)
    x = np.column_stack([v_source, z_nk])
    e = np.zeros_like(x)
    e[:, 0] = net.source_current
    e[k, np.arange(1, len(k) + 1)] = 1.0
    scale = abs(a) @ np.abs(x) + np.abs(e)
    with np.errstate(all="ignore"):
        error = np.abs(a @ x - e) / np.where(scale > 0, scale, 1.0)
    return float(error.max(initial=0.0)) if np.isfinite(error).all() else np.inf


@dataclass(frozen=True, eq=False)
class PhaseIterate:
    """S snapshots' power flow as the iteration left it, before its certificate
    (`certify`): `state` (S, r) what every node's voltage follows from — the currents J
    (S, |K|) that the branches and the load admittances inject at the nodes K (dense), or
    every node's V (S, n_node) (sparse) —, `settled` (S,) the last update was below the
    tolerance (and finite), `iterations` (S,); `at_k` (S, |K|) the voltages at K where
    they were already formed from `state` (`kept`), else None."""

    net: PhaseNetwork
    state: np.ndarray
    settled: np.ndarray
    iterations: np.ndarray
    at_k: np.ndarray | None = None

    @cached_property
    def v(self) -> np.ndarray:
        """(S, n_node) complex V of every node: V = A⁻¹·I_source + (A⁻¹)_{:,K}·J (dense)."""
        sys_ = _system(self.net)
        if sys_.z_nk is None:
            return self.state
        with one_blas_thread():
            return sys_.v_source + self.state @ sys_.z_nk.T

    @cached_property
    def v_k(self) -> np.ndarray:
        """(S, |K|) complex V at the nodes K: V_K = (A⁻¹·I_source)_K + Z_KK·J (dense)."""
        if self.at_k is not None:
            return self.at_k
        sys_ = _system(self.net)
        if sys_.z_kk is None:
            return self.state[:, sys_.k]
        with one_blas_thread():
            return sys_.v_source[sys_.k] + self.state @ sys_.z_kk.T

    @cached_property
    def der_vm(self) -> np.ndarray:
        """(S, n_der) the voltage each DER measures, p.u. (`PhaseFlowResult.der_vm`), from
        the voltages at K alone."""
        sys_ = _system(self.net)
        to = np.where(sys_.der_b < len(sys_.k), sys_.der_b, GROUND)  # K's ground position m → GROUND
        return _measured(self.net, _magnitude_across(self.v_k, sys_.der_a, to))

    @property
    def kept(self) -> np.ndarray:
        """(S, r') what a closed loop keeps of each snapshot (`resumed` gives the iterate
        back): dense, the state and V_K side by side (S, 2·|K|), so that V_K is formed once
        per iterate; sparse, the state (V_K is among its columns)."""
        if _system(self.net).z_kk is None:
            return self.state
        return np.concatenate([self.state, self.v_k], axis=1)

    @classmethod
    def resumed(cls, net: PhaseNetwork, kept: np.ndarray, settled: np.ndarray, iterations: np.ndarray) -> "PhaseIterate":
        """The iterate of snapshots a closed loop kept (`kept`)."""
        m = len(_system(net).k)
        if _system(net).z_kk is None:
            return cls(net, kept, settled, iterations)
        return cls(net, kept[:, :m], settled, iterations, kept[:, m:])


def voltages_within(now: PhaseIterate, before: PhaseIterate, tol: float) -> np.ndarray:
    """(S',) whether no node's |V| (p.u. of its base) moved by more than `tol` from the
    iterate `before` to `now` (S' snapshots each, of one network). Dense, first from the
    nodes K alone (their voltages `PhaseIterate.v_k`): a change above tol (by more than
    round-off) at one of them decides "no"; every node's voltages, both iterates' in one
    product, decide the rest."""
    net = now.net
    sys_ = _system(net)
    within = np.zeros(now.state.shape[0], dtype=bool)
    rows = np.arange(now.state.shape[0])
    with one_blas_thread():
        if sys_.z_kk is not None and sys_.z_nk is not None and rows.size:
            moved_k = _largest_change(now.v_k.T, before.v_k.T, 1.0 / sys_.base_k[:, 0], True)
            rows = np.flatnonzero(moved_k <= tol + _ROUND_OFF_PU)
            every = sys_.z_nk @ np.concatenate([now.state[rows], before.state[rows]]).T  # V − A⁻¹·I_source
            at_now, at_before, shift = every[:, : len(rows)], every[:, len(rows) :], sys_.v_source
        else:
            at_now, at_before, shift = now.state.T, before.state.T, None
    if rows.size:
        within[rows] = _largest_change(at_now, at_before, 1.0 / net.node_base_v, True, shift) <= tol
    return within


def _measured(net: PhaseNetwork, magnitude: np.ndarray) -> np.ndarray:
    """(S, n_der) each DER's measured voltage from its branches' |V| (S, n_der_branch) V:
    in p.u. of the branch base, averaged over the unit's branches."""
    u = magnitude / net.der_branches.vbase_v
    return np.asarray((net.der_measure @ u.T).T)


def _magnitude_across(v: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(S, len(a)) |V_a − V_b| (|V_a| where b is GROUND) of node voltages v (S, n_node)."""
    out = np.abs(v[:, a])
    to = np.flatnonzero(b != GROUND)
    if to.size:
        out[:, to] = np.abs(v[:, a[to]] - v[:, b[to]])
    return out


def _powers(label: str, values: np.ndarray | None, n_snap: int, n: int) -> np.ndarray:
    if values is None:
        return np.zeros((n_snap, n))
    arr = np.asarray(values, dtype=float)
    if arr.shape != (n_snap, n):
        raise InputError(f"three-phase power flow: {label} must have shape ({n_snap}, {n}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"three-phase power flow: {label} contains NaN or inf")
    return arr


def _checked_powers(
    net: PhaseNetwork, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray | None, der_q_mvar: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The four power arrays (S, n) of S snapshots — S from the load P's rows, a DER power
    None as zeros — checked for shape and finite values (`InputError` naming the array)."""
    load_p = np.atleast_2d(np.asarray(load_p_mw, dtype=float))
    n_snap = load_p.shape[0]
    return (
        _powers("load P", load_p, n_snap, net.n_load),
        _powers("load Q", load_q_mvar, n_snap, net.n_load),
        _powers("DER P", der_p_mw, n_snap, len(net.ders)),
        _powers("DER Q", der_q_mvar, n_snap, len(net.ders)),
    )


_Powers = tuple[np.ndarray, np.ndarray, np.ndarray]
"""The branches' powers (n_branch, S): load P (W) and Q (var) at their law's reference,
DER complex power generated (W + j var)."""


@dataclass(frozen=True, eq=False)
class BranchLoads:
    """S snapshots' load-element powers spread over the load branches (`branch_loads`):
    `p` W and `q` var (n_load_branch, S) at their law's reference — spread once for the
    many flows of a closed loop, each on some of the snapshots (`columns`)."""

    p: np.ndarray
    q: np.ndarray

    def columns(self, rows: np.ndarray) -> "BranchLoads":
        """The snapshots `rows`."""
        return BranchLoads(np.take(self.p, rows, axis=1), np.take(self.q, rows, axis=1))  # row-major, as the kernel reads them


def branch_loads(net: PhaseNetwork, load_p_mw: np.ndarray, load_q_mvar: np.ndarray) -> BranchLoads:
    """Each load element's P and Q (S, n_load) MW/MVAr at its law's reference, checked
    (`_checked_powers`) and spread over its branches."""
    load_p, load_q, _, _ = _checked_powers(net, load_p_mw, load_q_mvar, None, None)
    lb = net.load_branches
    return BranchLoads(load_p.T[lb.owner] * lb.share[:, None] * 1e6, load_q.T[lb.owner] * lb.share[:, None] * 1e6)


def _branch_powers(net: PhaseNetwork, loads: BranchLoads, der_p_mw: np.ndarray | None, der_q_mvar: np.ndarray | None) -> _Powers:
    """The load branches' powers and each DER's P and Q (S, n_der) MW/MVAr generated
    (None: 0; checked as `_checked_powers` does) spread over its branches."""
    n_snap = loads.p.shape[1]
    der_p = _powers("DER P", der_p_mw, n_snap, len(net.ders))
    der_q = _powers("DER Q", der_q_mvar, n_snap, len(net.ders))
    db = net.der_branches
    return loads.p, loads.q, (der_p.T + 1j * der_q.T)[db.owner] * db.share[:, None] * 1e6


def solve_phase_flow(
    net: PhaseNetwork,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray | None = None,
    der_q_mvar: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    tol: float = SWEEP_TOLERANCE,
    max_iter: int = MAX_SWEEP_ITER,
) -> PhaseFlowResult:
    """The power flow of S snapshots (module docstring): each load element's P and Q
    (S, n_load) MW/MVAr at its law's reference voltage (constant power: its power; constant
    Z or I: its power at the base voltage), each DER's P and Q (S, n_der) MW/MVAr
    generated (default 0); `v0` (S, n_node) complex V an optional warm start (rows that
    are not finite and non-zero start from the no-load state)."""
    load_p, load_q, der_p, der_q = _checked_powers(net, load_p_mw, load_q_mvar, der_p_mw, der_q_mvar)
    if net.tap_control and net.regulators:
        return _solve_controlled(net, load_p, load_q, der_p, der_q, v0, tol, max_iter)
    return _solve_fixed(net, load_p, load_q, der_p, der_q, v0, tol, max_iter)


@lru_cache(maxsize=64)
def tapped(net: PhaseNetwork, positions: tuple[int, ...]) -> PhaseNetwork:
    """`net.with_tap_positions(positions)`, one object per (network, positions): what is
    built for it (a factorization, a compiled OPF) serves every snapshot at those taps."""
    return net.with_tap_positions(positions)


def _solve_controlled(net, load_p, load_q, der_p, der_q, v0, tol, max_iter) -> PhaseFlowResult:
    """`solve_phase_flow` with the regulators' control loop (module docstring), on
    checked arrays (S, n)."""
    regs = net.regulators
    n_snap = load_p.shape[0]
    state = ControlState.start(regs, n_snap)
    v = np.zeros((n_snap, net.n_node), dtype=complex) if v0 is None else np.array(v0, dtype=complex).reshape(n_snap, net.n_node)
    converged = np.zeros(n_snap, dtype=bool)
    iterations = np.zeros(n_snap, dtype=np.int64)
    mismatch = np.full(n_snap, np.inf)
    losses = np.full(n_snap, np.nan)
    active = np.arange(n_snap)
    for _ in range(MAX_CONTROL_ITER):
        groups: dict[tuple[int, ...], list[int]] = {}
        for row in active.tolist():
            groups.setdefault(tuple(state.position[row].tolist()), []).append(row)
        for positions, rows_list in groups.items():
            rows = np.array(rows_list)
            flow = _solve_fixed(
                tapped(net, positions), load_p[rows], load_q[rows], der_p[rows], der_q[rows], v[rows], tol, max_iter
            )
            v[rows], converged[rows], mismatch[rows], losses[rows] = flow.v, flow.converged, flow.mismatch, flow.losses_kw
            iterations[rows] += flow.iterations
        sub = ControlState(state.position[active], state.armed[active], state.pending[active])
        for i, reg in enumerate(regs):
            nodes = net.elements[reg.element].nodes
            sample(reg, i, sub, control_voltage(reg, nodes, v[active], reg.yprims[sub.position[:, i]]))
        going = act(regs, sub) & converged[active]  # a diverged snapshot stops its control loop, as OpenDSS's does
        state.position[active], state.armed[active], state.pending[active] = sub.position, sub.armed, sub.pending
        active = active[going]
        if not active.size:
            break
    else:
        converged[active] = False  # still armed after MAX_CONTROL_ITER rounds: not settled
    return PhaseFlowResult(net, v, converged, iterations, mismatch, losses, state.position.copy())


def _solve_fixed(
    net: PhaseNetwork,
    load_p: np.ndarray,
    load_q: np.ndarray,
    der_p: np.ndarray,
    der_q: np.ndarray,
    v0: np.ndarray | None,
    tol: float,
    max_iter: int,
) -> PhaseFlowResult:
    """`solve_phase_flow` at the taps the network's elements have (arrays as `solve_phase_flow` checked them)."""
    powers = _branch_powers(net, branch_loads(net, load_p, load_q), der_p, der_q)
    sys_ = _system(net)
    start = None
    if v0 is not None:
        n_snap = powers[0].shape[1]
        start = np.asarray(v0, dtype=complex).reshape(n_snap, net.n_node).T
        start = start if sys_.z_nk is None else start[sys_.k]
    return _certify(_iterate(net, sys_, powers, start, tol, max_iter), sys_, powers)


def iterate_phase_flow(
    net: PhaseNetwork,
    loads: BranchLoads,
    der_p_mw: np.ndarray | None = None,
    der_q_mvar: np.ndarray | None = None,
    start: PhaseIterate | None = None,
    tol: float = SWEEP_TOLERANCE,
    max_iter: int = MAX_SWEEP_ITER,
) -> PhaseIterate:
    """The iteration of `solve_phase_flow` without its certificate (`certify`) on the
    loads `loads` of S snapshots (`branch_loads`), warm started from an earlier iterate of
    the same S snapshots on the same network (`start`)."""
    if net.tap_control and net.regulators:
        raise ValueError(f"{net.name}: regulators under tap control move inside the solve; iterate with solve_phase_flow")
    powers = _branch_powers(net, loads, der_p_mw, der_q_mvar)
    sys_ = _system(net)
    carried = None
    if start is not None:  # the carried nodes' voltages of the earlier iterate
        carried = start.state.T if sys_.z_kk is None else start.v_k.T
    return _iterate(net, sys_, powers, carried, tol, max_iter)


def certify(
    flow: PhaseIterate, loads: BranchLoads, der_p_mw: np.ndarray | None, der_q_mvar: np.ndarray | None
) -> PhaseFlowResult:
    """The certified power flow of an iterate at the powers it was solved for (the loads
    `branch_loads`): every node's voltage, the mismatch (`_residual`), the losses;
    converged = settled and the mismatch below `MISMATCH_REL`."""
    return _certify(flow, _system(flow.net), _branch_powers(flow.net, loads, der_p_mw, der_q_mvar))


def _iterate(
    net: PhaseNetwork, sys_: _System, powers: _Powers, start: np.ndarray | None, tol: float, max_iter: int
) -> PhaseIterate:
    """The iteration on S snapshots from `start` (r, S) (the carried nodes' V, or None:
    the no-load state; columns that are not finite and non-zero start from it too)."""
    n_snap = powers[0].shape[1]
    m = len(sys_.k)
    dense = sys_.z_nk is not None
    rows = sys_.k if dense else np.arange(net.n_node)  # the nodes the iteration carries
    no_load = sys_.v_source[rows]
    v = np.repeat(no_load[:, None], n_snap, axis=1) if start is None else _started(no_load, start)
    at_k = np.arange(m) if dense else sys_.k  # K's rows in v
    iterations = np.zeros(n_snap, dtype=np.int64)
    settled = np.full(n_snap, m == 0)  # nothing voltage-dependent: the no-load state is the answer
    active = np.arange(n_snap)
    v_act, p_act = v, powers
    v_source_k = sys_.v_source[sys_.k][:, None]
    per_base = 1.0 / sys_.base_k[:, 0]
    with one_blas_thread(), np.errstate(all="ignore"):
        for it in range(1, max_iter + 1 if m else 1):
            v_k = v_act if dense else v_act[at_k]
            j = sys_.iteration_currents(v_k, *p_act)
            if dense:
                new = sys_.z_kk @ j
                new += v_source_k
                step = _largest_change(new, v_k, per_base, False)
            else:
                rhs = np.zeros((net.n_node, j.shape[1]), dtype=complex, order="F")
                rhs[sys_.k] = j
                new = sys_.v_source[:, None] + sys_.lu.solve(rhs)
                step = _largest_change(np.ascontiguousarray(new[at_k]), v_k, per_base, False)
            iterations[active] = it
            done = step < tol
            settled[active[done]] = True
            keep = ~done & np.isfinite(step)
            if keep.all():
                v_act = new
                continue
            v[:, active[~keep]] = new[:, ~keep]
            if not keep.any():
                break
            active = active[keep]  # compress keeps the columns row-major, as the current kernel reads them (no copy there)
            v_act = np.compress(keep, new, axis=1)
            p_act = (
                np.compress(keep, p_act[0], axis=1),
                np.compress(keep, p_act[1], axis=1),
                np.compress(keep, p_act[2], axis=1),
            )
        else:
            v[:, active] = v_act
        if dense:  # the currents every node's voltage follows from: V = A⁻¹·(I_source + P_K·J)
            state = sys_.iteration_currents(v, *powers).T.copy()
        else:
            state = np.ascontiguousarray(v.T)
    return PhaseIterate(net, state, settled, iterations)


@njit(cache=True)
def _started(no_load: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(r, S) the iteration's first voltages: each column of `start` (r, S) that is finite
    and not all zero, else the no-load state `no_load` (r,)."""
    r, n = start.shape
    out = np.empty((r, n), dtype=np.complex128)
    for s in range(n):
        usable, nonzero = True, False
        for i in range(r):
            z = start[i, s]
            usable = usable and np.isfinite(z.real) and np.isfinite(z.imag)
            nonzero = nonzero or z != 0
        for i in range(r):
            out[i, s] = start[i, s] if usable and nonzero else no_load[i]
    return out


@njit(cache=True, error_model="numpy")
def _largest_change(
    new: np.ndarray, old: np.ndarray, per_base: np.ndarray, magnitudes: bool, shift: np.ndarray | None = None
) -> np.ndarray:
    """(S,) the largest |new − old| (m, S) of a column — with `magnitudes` the largest
    ||new| − |old|| — in p.u. of each row's base (per_base = 1/base); NaN where some is NaN.
    `shift` (m,) is added to each row of both first (as `+=` would, without forming them)."""
    m, n = new.shape
    out = np.zeros(n)
    for i in range(m):
        for s in range(n):
            a, b = new[i, s], old[i, s]
            if shift is not None:
                a, b = a + shift[i], b + shift[i]
            if magnitudes:
                moved = abs(np.sqrt(a.real * a.real + a.imag * a.imag) - np.sqrt(b.real * b.real + b.imag * b.imag))
            else:
                moved = np.sqrt((a.real - b.real) ** 2 + (a.imag - b.imag) ** 2)
            moved *= per_base[i]
            if moved > out[s] or moved != moved:
                out[s] = moved
    return out


def _certify(flow: PhaseIterate, sys_: _System, powers: _Powers) -> PhaseFlowResult:
    """`certify`. Dense: every node's voltage V = A⁻¹·I_source + Z_NK·J in one product,
    node-major (n_node, S) (the result's `v` is its transpose); the mismatch on K from Y's rows K (the nodes they join), every other
    node's being the network's `linear_error` (`_linear_error`). Sparse: the iterate's
    voltages, the mismatch at every node (`_certify_every_node`)."""
    if sys_.z_nk is None:
        return _certify_every_node(flow, sys_, powers)
    net = flow.net
    with one_blas_thread(), np.errstate(all="ignore"):
        nodes_major = sys_.z_nk @ flow.state.T
        nodes_major += sys_.v_source[:, None]
        given = sys_.injections(nodes_major[sys_.k], *powers)
        at_k = _residual(sys_.y_k_near, nodes_major[sys_.near], net.source_current[sys_.k], given, slice(None))
        losses = _source_kva(net, nodes_major).real + (nodes_major[sys_.k] * np.conj(given)).real.sum(axis=0) / 1e3
    mismatch = np.maximum(at_k, sys_.linear_error)
    converged = np.asarray(flow.settled, dtype=bool) & (mismatch < MISMATCH_REL)
    return PhaseFlowResult(net, nodes_major.T, converged, flow.iterations, mismatch, losses)


def _certify_every_node(flow: PhaseIterate, sys_: _System, powers: _Powers) -> PhaseFlowResult:
    """`certify` of the sparse iteration (its state is every node's V), in blocks of
    snapshots whose node voltages take `_BLOCK_BYTES` (they stay in cache through the
    residual and the losses), node-major (n_node, S), the layout the sparse products want;
    the result's `v` is its transpose."""
    net = flow.net
    n_snap = flow.state.shape[0]
    size = max(1, _BLOCK_BYTES // (16 * net.n_node))
    v = np.empty((net.n_node, n_snap), dtype=complex)
    mismatch = np.empty(n_snap)
    losses = np.empty(n_snap)
    with one_blas_thread(), np.errstate(all="ignore"):
        for first in range(0, n_snap, size):
            block = slice(first, first + size)
            vb = np.ascontiguousarray(flow.state[block].T)
            given = sys_.injections(vb[sys_.k], powers[0][:, block], powers[1][:, block], powers[2][:, block])
            mismatch[block] = _residual(net.ybus, vb, net.source_current, given, sys_.k, sys_.ybus_abs)
            losses[block] = _source_kva(net, vb).real + (vb[sys_.k] * np.conj(given)).real.sum(axis=0) / 1e3
            v[:, block] = vb
    converged = np.asarray(flow.settled, dtype=bool) & (mismatch < MISMATCH_REL)
    return PhaseFlowResult(net, v.T, converged, flow.iterations, mismatch, losses)


def _source_kva(net: PhaseNetwork, v: np.ndarray) -> np.ndarray:
    """(S,) complex power the source delivers into its bus (kW + j kvar) at node voltages
    v (n_node, S)."""
    s = net.source
    at = v[s.nodes]
    current = s.y_s @ (s.emf_v[:, None] - at)
    return (at * np.conj(current)).sum(axis=0) / 1e3


def _residual(
    y: sp.spmatrix, v: np.ndarray, source: np.ndarray, given: np.ndarray, at: np.ndarray | slice, y_abs: sp.spmatrix | None = None
) -> np.ndarray:
    """(S,) the componentwise backward error of the network equations on Y's rows `y`
    (their columns' voltages v (·, S)): the largest nodal current mismatch
    |Y·V − I_source − I_branches| relative to the currents that meet at the node
    (|Y|·|V| + |I_source| + |I_branches|), the branch currents `given` injected at the
    rows `at`. Scale-free, so a node joined by a near-zero impedance switch — whose
    currents are large differences of large terms and carry their round-off — is judged
    against what round-off leaves there."""
    residual = y @ v - source[:, None]
    residual[at] -= given
    scale = (abs(y) if y_abs is None else y_abs) @ np.abs(v) + np.abs(source)[:, None]
    scale[at] += np.abs(given)
    with np.errstate(all="ignore"):
        error = np.abs(residual) / np.where(scale > 0, scale, 1.0)
    return np.where(np.isfinite(error).all(axis=0), error.max(axis=0, initial=0.0), np.inf)
