"""LinDist3Flow: the linearized multiphase branch flow of a radial unbalanced feeder (Gan &
Low, PSCC 2014; Arnold et al.; PowerModelsDistribution's LPUBFDiagPowerModel), an
approximation of `ac_three_phase`'s problem — fast, and neither a bound nor an optimum.

LinDist3Flow drops the losses from the flows and takes every current at the nominal
voltage: a branch carries the power its subtree draws, S_ij ≈ Γ·diag(s) with Γ_φψ =
a_φ·conj(a_ψ) the ratio of the phases' nominal phasors (balanced nominal: a = (1, α², α),
α = e^{−j2π/3}, PMD's γ = [[1, α², α], [α, 1, α²], [α², α, 1]]), and the squared voltage
magnitudes v = |V|² drop linearly along it:

    v_j = v_i − 2·Re{ conj(Γ) ∘ Z · conj(s) }        (per phase of a line; p.u.²)

Here it is written on the node-level model every other three-phase model shares
(`PhaseNetwork.ybus`: lines, switches, transformers and regulators at their fixed taps,
the source's EMF behind its Thevenin admittance), with two generalisations that keep it
exact for elements the textbook form handles by special cases:

- the nominal point is the feeder's own no-load voltage v⁰ = Y⁻¹·i_source (loads and DER
  off: a linear network), not 1∠(0, −120°, 120°) — its angles are the phases' nominal
  phasors (so Γ also carries a Dy transformer's 30° shift), its magnitudes the regulators'
  fixed taps and the line charging;
- each load and DER draws its current at that nominal voltage, i = conj(S / w⁰) (w⁰ its
  branch voltage, phase to neutral or phase to phase: delta units included), S at the
  load law's reference (constant power at 1 p.u.: constant Z and I loads at their
  nominal power, as LinDist3Flow's constant-power loads) and the DER's P + jQ; the voltage
  change is δV = Y⁻¹·(the currents), a sum over the path to the source of each branch's
  Z times the current its subtree draws — which per line is, to first order, the recursion above, and
  through a transformer its ratio and leakage impedance, delta windings' circulating
  currents included.

The band: lo² ≤ |m⁰|² + 2·Re{conj(m⁰)·δm} ≤ hi² for every monitored voltage m (the
linearized v = |V|², `PhaseNetwork.monitored`); DER Q within ±(1 − k)·Qmax. The
objective estimates the losses as the power the network's elements dissipate at the
linearized voltages, Re{Vᴴ·H·V} with H the Hermitian part of the elements' admittance
(the source's Thevenin impedance excluded, as the power flow's losses): Σ over branches of
Re{Iᴴ·Z·I} at the linear model's currents — the three-phase counterpart of lindistflow's
Σ r·(P² + Q²)/v² — a convex quadratic in Q (kW). `slack_export=False` refuses a snapshot
whose lossless balance exports (the loads' reference power below the DER's).

The problem is built once per feeder: Y is factorized once, the sensitivities of the
monitored voltages and of the losses to each DER's Q are constant, and the data enter as
cvxpy Parameters of a program compiled once (`_Program`; Clarabel solves it). Of the band's
rows (one per monitored voltage: 2721 on eulv) only a few can bind, so the program holds a
working set of them in parameter slots: the rows that Q within its limits can push out of
the band (the others never bind), starting from those already out at Q = 0, adding the
rows the answer violates until none is (a program with twice the slots is compiled when the
set outgrows it) — the answer of the full program, from the snapshot's data alone. Its
setpoints are evaluated by the three-phase power flow like every formulation's
(`three_phase.run_phase_batch`); its objective is the estimate the report sets against
their AC losses, and `predict` the voltages it expects, which the runner compares with the
power flow's (`vm_error_pu`).

Units: MW, MVAr (Q positive = injected), kW for losses, p.u. voltages.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from opfbench.errors import NetworkError
from opfbench.formulations.model import formulation
from opfbench.formulations.models.ac_three_phase import BranchEnds
from opfbench.multiphase import GROUND, Branches, PhaseNetwork
from opfbench.threads import one_blas_thread

KW_PER_MW = 1e3
SLOTS = 16
"""Band rows the compiled program holds at first (doubled when the working set outgrows it)."""
MAX_ROUNDS = 20
"""Rounds of adding violated band rows to the working set before a snapshot is given up."""
BAND_TOL = 1e-7
"""p.u.² by which a band row outside the working set may be violated (Clarabel's feasibility
tolerance on the rows inside it)."""


@dataclass(frozen=True)
class LinearSolve:
    """One snapshot's LinDist3Flow answer: `q_mvar` (n_der,; None unless optimal),
    `objective_kw` (its loss estimate; NaN unless optimal), `status` (cvxpy's), `optimal`,
    `infeasible` (the linearized band cannot be met, or the slack would export where it
    may not), `solve_ms` (the call, wall clock), `iterations` (Clarabel's)."""

    q_mvar: np.ndarray | None
    objective_kw: float
    status: str
    optimal: bool
    infeasible: bool
    solve_ms: float
    iterations: int


def _owner_map(br: Branches, n_owner: int) -> sp.csr_matrix:
    """(n_branch, n_owner): each branch's share of its element's power."""
    return sp.csr_matrix((br.share, (np.arange(br.n), br.owner)), shape=(br.n, n_owner))


@formulation(
    "lindist3flow",
    role="approximation",
    networks=("unbalanced-radial",),
    summary="LinDist3Flow (linearized multiphase branch flow, currents at the no-load voltage, losses estimated as "
    "Re VᴴHV at its voltages): fast approximation; its Q evaluated by the three-phase power flow",
)
class LinDist3Flow:
    """LinDist3Flow on a radial three-phase feeder (module docstring); `solve` one snapshot,
    `predict` the monitored voltages at given setpoints. NetworkError for a meshed feeder."""

    def __init__(self, net: PhaseNetwork, slack_export: bool = True):
        if net.meshed:
            raise NetworkError(f"{net.name}: LinDist3Flow linearizes the branch flow of a radial feeder; this one is meshed")
        self.net, self.slack_export = net, slack_export
        base = net.node_base_v
        y = (sp.diags(base) @ net.ybus @ sp.diags(base) / 1e6).tocsc()  # p.u. on 1 MVA and each node's base
        src = net.source
        i_src = np.zeros(net.n_node, dtype=complex)
        i_src[src.nodes] = (src.y_s @ src.emf_v) * base[src.nodes] / 1e6
        lu = spla.splu(y)
        self.v0 = lu.solve(i_src)  # the no-load point (p.u.)
        n_der = len(net.ders)

        def currents(br: Branches, n_owner: int) -> np.ndarray:
            """(n_node, n_owner) δV per unit of conj(S) of each element, drawn as an
            injection at the no-load voltage."""
            if not br.n:
                return np.zeros((net.n_node, n_owner), dtype=complex)
            ends = BranchEnds.of(net, br)
            w0 = self.v0[ends.a] - ends.ratio_b * np.append(self.v0, 0.0)[ends.b]
            per_branch = ends.inject @ sp.diags(1.0 / np.conj(w0)) @ _owner_map(br, n_owner)
            return lu.solve(np.asarray(per_branch.toarray(), dtype=complex))

        a_der = currents(net.der_branches, n_der)  # δV = a_der·(p − jq) (injected)
        a_load = currents(net.load_branches, net.n_load)  # δV = −a_load·(p_load − j·q_load), the law's reference power
        a, b, base_m, _ = net.monitored
        rows = np.arange(len(a))
        scale = base[a] / base_m
        ground = b == GROUND
        mon = sp.csr_matrix(
            (np.concatenate([scale, -scale[~ground]]), (np.concatenate([rows, rows[~ground]]), np.concatenate([a, b[~ground]]))),
            shape=(len(a), net.n_node),
        )
        self._mon = mon
        self.m0 = mon @ self.v0
        # the losses: Re VᴴHV, H the Hermitian part of the elements' admittance (source's excluded)
        source_block = sp.coo_matrix(np.diag(base[src.nodes]) @ src.y_s @ np.diag(base[src.nodes]) / 1e6)
        y_net = y - sp.csc_matrix((source_block.data, (src.nodes[source_block.row], src.nodes[source_block.col])), shape=y.shape)
        self._h = ((y_net + y_net.conj().T) / 2).tocsr()
        self._a_der, self._a_load = a_der, a_load
        b_q = -1j * a_der  # δV per MVAr of Q
        hess = (b_q.conj().T @ (self._h @ b_q)).real
        lam, vec = np.linalg.eigh((hess + hess.T) / 2)
        self._b_q = b_q
        factor = (np.sqrt(np.clip(lam, 0.0, None))[:, None] * vec.T) * np.sqrt(KW_PER_MW)

        self._w_q = 2.0 * (np.conj(self.m0)[:, None] * (mon @ b_q)).real  # ∂|m|²/∂q (n_monitored, n_der)
        self._factor = factor
        self._programs: dict[int, _Program] = {}

    # ----- the linear model -----------------------------------------------------------
    def _voltage(self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray) -> np.ndarray:
        """(n_node,) complex p.u.: the linearized voltages at Q = 0."""
        drawn = np.asarray(load_p_mw, dtype=float) - 1j * np.asarray(load_q_mvar, dtype=float)  # conj(S)
        return self.v0 - self._a_load @ drawn + self._a_der @ np.asarray(der_p_mw, dtype=float)

    def predict(self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_mvar: np.ndarray) -> np.ndarray:
        """(n_monitored,) the monitored voltages (p.u., `PhaseNetwork.monitored`) the model
        predicts at these loads (n_load,) and DER P and Q (n_der,): √ of its linear |V|²."""
        m = self._mon @ self._voltage(load_p_mw, load_q_mvar, der_p_mw)
        w = (np.abs(self.m0) ** 2 + 2.0 * (np.conj(self.m0) * (m - self.m0)).real) + self._w_q @ np.asarray(q_mvar, float)
        return np.sqrt(np.maximum(w, 0.0))

    def solve(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> LinearSolve:
        """One snapshot: loads' P and Q (n_load,) at their law's reference, DER P and usable
        |Q| (n_der,), MW/MVAr. BLAS on one thread: its products are small, and threads
        waiting on a shared machine cost more than the work."""
        with one_blas_thread():
            return self._solve(load_p_mw, load_q_mvar, der_p_mw, q_limit_mvar)

    def _solve(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> LinearSolve:
        start = time.perf_counter()
        if not self.slack_export and float(np.sum(load_p_mw) - np.sum(der_p_mw)) < 0:
            return LinearSolve(None, np.nan, "infeasible (the slack would export)", False, True, 0.0, 0)
        c = self._voltage(load_p_mw, load_q_mvar, der_p_mw)
        m = self._mon @ c
        hc = self._h @ c
        limit = np.maximum(np.asarray(q_limit_mvar, dtype=float), 0.0)
        linear = 2.0 * KW_PER_MW * (self._b_q.conj().T @ hc).real
        offset = np.abs(self.m0) ** 2 + 2.0 * (np.conj(self.m0) * (m - self.m0)).real
        lo, hi = (x**2 for x in self.net.band)
        reach = np.abs(self._w_q) @ limit  # how far Q can move each row
        candidate = (offset + reach > hi - BAND_TOL) | (offset - reach < lo + BAND_TOL)  # the others never bind
        worst = np.maximum(offset - hi, lo - offset)  # at Q = 0
        working = np.flatnonzero(candidate & (worst > -BAND_TOL))  # from the snapshot's data alone
        status, q, value, iterations = "", None, np.nan, 0
        for _ in range(MAX_ROUNDS):
            program = self._program(working.size)
            status, q, value, its = program.solve(self._w_q[working], offset[working], limit, linear, (lo, hi))
            iterations += its
            if q is None:
                break
            w = offset + self._w_q @ q
            outside = candidate & ((w > hi + BAND_TOL) | (w < lo - BAND_TOL))
            outside[working] = False  # those are the solver's, at its tolerance
            if not outside.any():
                break
            working = np.union1d(working, np.flatnonzero(outside))
        else:
            status = "working set did not settle"
        ms = (time.perf_counter() - start) * 1e3
        if q is None or status != cp.OPTIMAL:
            return LinearSolve(None, np.nan, status, False, status == cp.INFEASIBLE, ms, iterations)
        constant = KW_PER_MW * float(np.real(np.vdot(c, hc)))
        return LinearSolve(q, value + constant, status, True, False, ms, iterations)

    def _program(self, rows: int) -> _Program:
        """The compiled program with room for `rows` band rows (slots of SLOTS, doubled as needed)."""
        size = SLOTS
        while size < rows:
            size *= 2
        if size not in self._programs:
            self._programs[size] = _Program(self._factor, size)
        return self._programs[size]


class _Program:
    """The QP over Q with `slots` band rows as cvxpy Parameters (compiled at the first solve,
    re-solved with new data): minimize ‖F·q‖² + c·q subject to |q| ≤ limit and
    lo² ≤ w₀ + W·q ≤ hi² on the rows given; unused slots hold 0·q = (lo² + hi²)/2."""

    def __init__(self, factor: np.ndarray, slots: int):
        n_der = factor.shape[1]
        self.q = cp.Variable(n_der, name="q")
        self.limit = cp.Parameter(n_der, nonneg=True, name="q_limit")
        self.linear = cp.Parameter(n_der, name="loss_linear")
        self.rows = cp.Parameter((slots, n_der), name="band_rows")
        self.offset = cp.Parameter(slots, name="band_offset")
        self.lo, self.hi = cp.Parameter(name="lo"), cp.Parameter(name="hi")
        w = self.offset + self.rows @ self.q
        constraints = [cp.abs(self.q) <= self.limit, w >= self.lo, w <= self.hi]
        self.problem = cp.Problem(cp.Minimize(cp.sum_squares(factor @ self.q) + self.linear @ self.q), constraints)
        self.slots = slots

    def solve(
        self, rows: np.ndarray, offset: np.ndarray, limit: np.ndarray, linear: np.ndarray, band: tuple[float, float]
    ) -> tuple[str, np.ndarray | None, float, int]:
        """(status, q or None, objective, Clarabel's iterations) for these band rows."""
        full_rows = np.zeros((self.slots, rows.shape[1]))
        full_offset = np.full(self.slots, (band[0] + band[1]) / 2)
        full_rows[: len(rows)], full_offset[: len(rows)] = rows, offset
        self.rows.value, self.offset.value = full_rows, full_offset
        self.limit.value, self.linear.value = limit, linear
        self.lo.value, self.hi.value = band
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # cvxpy's "inaccurate": the status says it
                self.problem.solve(solver=cp.CLARABEL)
            status = str(self.problem.status)
        except cp.error.SolverError:
            status = "solver_error"
        stats = self.problem.solver_stats
        iterations = int(stats.num_iters or 0) if stats is not None else 0
        if status != cp.OPTIMAL or self.q.value is None:
            return status, None, np.nan, iterations
        return status, np.array(self.q.value), float(self.problem.value), iterations
