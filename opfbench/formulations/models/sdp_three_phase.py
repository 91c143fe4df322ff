"""The SDP relaxation of the three-phase OPF on radial feeders, in branch-flow form (Gan &
Low, PSCC 2014; PowerModelsDistribution's SDPUBFPowerModel): a certified lower bound on the
losses of `ac_three_phase`'s problem (cvxpy + Clarabel's PSD cones).

Every two-terminal element between buses i → j (downstream from the source), and the
elements in parallel between the same two buses (a regulator bank) as one branch, is
written in impedance form — never through its admittance, whose near-zero-impedance
switches, regulators and stiff source reach 1e6 p.u. and left an earlier bus-injection
draft with coefficients from 1e-9 to 2e4 (Clarabel: NumericalError):

    C_p·v_i − C_s·v_j = Z·I,   current C_pᵀ·I drawn from i's nodes, C_sᵀ·I delivered to j's

with `shunt` admittances at either end. A line (and switch): C_p = C_s = identity, Z its
phase impedance matrix and half its shunt at each end, as OpenDSS's π model. A transformer
or regulator: one core per phase unit, C_p and C_s the winding's node incidences (wye:
phase − neutral, delta: phase − next phase, one-phase: conductor 1 − conductor 2), C_s
scaled by the core's ratio at the *fixed* tap, Z the leakage impedance of each core —
fitted to OpenDSS's own primitive admittance and checked to reproduce it (relative
`FIT_RTOL`; refused otherwise; the ratio is kept complex, real up to OpenDSS's round-off,
which a real ratio turns into 1e-7 p.u. of power per node), and its anti-float shunts.
So a transformer or regulator is the exact model's element — an ideal voltage ratio at
the fixed tap (v_j = v_i/t per core, the lossless ideal-transformer flow relation) plus
its own series impedance, whose losses stay in the objective: nothing about it is
relaxed beyond rank, and the relaxation stays a bound on the problem with taps held (the
exact model's). A line (a switch) whose impedance is below `Z_IDEAL` p.u. is ideal: its
two ends share one voltage matrix and it carries each conductor's power unchanged — the
exact model's voltage drop there (below Z_IDEAL·|I|) and its losses (below
Z_IDEAL·|I|²) are dropped, the one place the relaxation is not of the exact model
itself. The source: its EMF e·ξ (the three phase voltages fixed, ξ the common
phase reference, |ξ| = 1) behind its Thevenin impedance, a branch of its own.

Each branch's free coordinates ζ are the sending nodes' voltages, the currents the
relation leaves free and the receiving voltages it leaves free (a delta winding's common
mode); the receiving voltages are linear in ζ (v_j = E_s·ζ). The relaxation lifts G = ζζᴴ
per branch and drops rank(G) = 1, keeping G ⪰ 0: the sending block of G equals the bus
matrix W_i that the parent branch gives (Gan–Low's W_j = W_i − (SZᴴ + ZSᴴ) + ZLZᴴ with
S = v_i·Iᴴ, L = I·Iᴴ, generalised to the ratio C_p, C_s). On a radial feeder these
cliques cover the exact model; a meshed feeder is refused (NetworkError).

Before lifting, every chain bus is eliminated (`ThreePhaseSdp._reduced`): a bus reached by
one shunt-free line and left by exactly one, on the same nodes and voltage base, with no
load, DER or shunt element there. Both lines carry the same current, so they are one line
of impedance Z₁ + Z₂ (the Kron reduction of a node with no injection: exact, losses
included). Only the band rows of the eliminated nodes (and the current cuts at them) go:
that loosens the relaxation, so its optimum stays a lower bound on the exact model's, whose
band holds at every node. A feeder whose lines are mostly such chains (eulv: a bus every
few metres of cable) keeps a block per load or DER bus and per junction instead of one per
bus.

Per unit: node voltages on their base (`PhaseNetwork.node_base_v`), powers on `s_base`
(the feeder's nominal load, ≥ 1 kVA), so line impedances are O(1e-4..1) and powers O(1).

Every other constraint of the exact model is linear in the lifted matrices or relaxed to
its convex hull, so the optimum is a bound on the exact model's:
- node balance: what the branches draw at a node (linear in G) = loads − DER;
- the band: lo² ≤ |v_a − v_b|²/base² ≤ hi² (linear in W);
- a load branch draws S₀·s(w), w = u²: constant Z s = w (exact); constant PQ s = 1 below
  vmaxpu and w/vmaxpu² above — relaxed to s ≥ max(1, w/vmaxpu²) and s ≤ the chord over
  w's range where the band bounds it; constant |I| and exponential laws s = w^(e/2) in
  [vminpu, vmaxpu] — relaxed to the region between the curve and its chord;
- a delta (or neutral-connected) load or DER branch a → b: its current lifted with v_a,
  v_b in a block of its own (S drawn = (v_a − v_b)·i*);
- DER: P fixed, Q a variable within ±(1 − k)·Qmax, each branch's voltage at or above
  `ac_three_phase.DER_VMIN_PU` (as in the exact model);
- valid cuts that hold at every operating point and bound what the objective leaves free:
  each lifted branch current |i|² ≤ |S|²/w at the worst end of w's range
  (`branch_caps`), and at every node the lifted |current fed to it|² ≤ k·Σ of the |·|² of
  the k currents it passes on (Kirchhoff and Cauchy–Schwarz, `_kcl_caps`). Without them a
  near-lossless element's (or the source's, whose Thevenin losses are in no objective
  term) current block grows at no cost and its mutual impedance moves power between
  phases, and the bound falls far below the optimum.

Where exactness is lost: a block of rank above one (`rank_one`, per block: the ratio of its
second to its first eigenvalue above `RANK_RATIO`); the hulls of voltage-dependent loads
(tight only at the ends of their range); delta branches, whose lifted current may split the
branch's power between its two nodes unlike any voltage (Alsaleh et al.); and, at a
regulator, the fixed tap (the bound is on the problem with taps held, as the exact model).
A floating delta winding's common mode is fixed only by tiny shunts, so an interior-point
solution inflates it and its block reads as rank two while nothing depends on it: the
rank check leaves it out where nothing downstream is referenced to ground (ieee123's xfm1,
`rank_ratios`); on ieee37 the whole feeder floats (its lines' charging to ground fixes
the common mode) and it is kept.

Only an "optimal" status gives a bound; "optimal_inaccurate" (Clarabel's AlmostSolved) and
solver errors give none, and "infeasible" proves the exact problem infeasible (its
Farkas certificate holds for the relaxation, which contains the exact feasible set).

Built once per feeder: loads, DER P and the Q limits are cvxpy Parameters; cvxpy compiles
the problem for Clarabel when it is built (so the build's time holds the compilation and a
solve only the parameters' update and Clarabel's run) and re-solves from the compiled form
(`solve`).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from opfbench.errors import NetworkError
from opfbench.formulations.model import formulation
from opfbench.formulations.models.ac_three_phase import DER_VMIN_PU, load_law
from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_PQ, CONSTANT_Z, EXPONENTIAL

RANK_RATIO = 1e-5
"""A block is rank one when its second eigenvalue is at most this fraction of its first."""
FIT_RTOL = 1e-7
"""An element's impedance form must reproduce its primitive admittance to this (relative)."""
KW_PER_MW = 1e3
_EPS2 = float(np.finfo(float).eps) ** 2
"""Clarabel's default proportional static regularisation (machine ε²)."""
CLARABEL_ATTEMPTS: tuple[dict[str, float], ...] = (
    {"static_regularization_constant": 1e-7, "static_regularization_proportional": _EPS2, "tol_feas": 1e-8},
    {"static_regularization_constant": 1e-7, "static_regularization_proportional": _EPS2, "tol_feas": 1e-7},
    {"static_regularization_constant": 1e-8, "static_regularization_proportional": _EPS2, "tol_feas": 1e-8},
    {"static_regularization_constant": 1e-6, "static_regularization_proportional": _EPS2, "tol_feas": 1e-8},
    {"static_regularization_constant": 1e-8, "static_regularization_proportional": 1e-12, "tol_feas": 1e-8},
)
"""Clarabel's settings, tried in turn until one ends optimal or infeasible: its static
regularisation at 1e-7 first, as the lifted blocks' near-zero directions (a near-lossless
regulator's or transformer's current) stall its KKT solves at its default 1e-8 (on ieee123
every step: an "almost solved" or a numerical error after ~20 iterations, as long as the
solve that follows); then its feasibility tolerance at 1e-7 (default 1e-8): with ieee13's
near-ideal regulators (XHL 0.01 %) the primal residual stalls at 3e-8 while the dual
residual is 1e-12 and the duality gap 2e-9 (AlmostSolved) — the bound is the reported
(primal) value, tied to the dual objective only by that gap, which is why
`three_phase.certify` takes it only where the relaxation's own point attains it; then the
default, then 1e-6; last the default constant with a proportional
part of 1e-12 (Clarabel's default: ε², 5e-32): on eulv, whose rank-one solutions stall
every other attempt's line search one step from the tolerances (AlmostSolved: the gap),
it ends optimal where the relaxation is exact (the night) — to Clarabel's accuracy only:
eulv's losses are under 1 % of the power it carries, so the residuals its tolerances
allow weigh a hundred times more on them, and its values there fall on either side of
the AC optimum by up to ~1e-5 (`docs/sdp_point_check.py`): a "bound" above the optimum is
that, and a 1e-6 certificate on eulv is within that noise. Each attempt names every
setting it changes: cvxpy re-uses a cached Clarabel solver (where its settings allow a
data update) with the previous attempt's settings as the base."""
Z_IDEAL = 1e-6
"""A line (a switch) whose series impedance is below this (p.u. on `s_base`) is ideal: its
ends share voltages and it carries each conductor's power unchanged (module docstring)."""


@dataclass(frozen=True)
class BoundSolve:
    """One snapshot's relaxation: `bound_kw` (NaN unless solved), `rank_ratio` (the largest
    second-to-first eigenvalue ratio over the blocks; NaN unless solved), `rank_one`
    (`rank_ratio` ≤ RANK_RATIO), `infeasible` (Clarabel certified the relaxation infeasible:
    so is the exact problem), `status` (cvxpy's), `solve_ms` (the call, wall clock) and
    `q_mvar` (n_der,) the relaxation's DER Q, MVAr, injected positive (NaN unless solved)."""

    bound_kw: float
    rank_ratio: float
    rank_one: bool
    infeasible: bool
    status: str
    solve_ms: float
    q_mvar: np.ndarray


@dataclass
class _Branch:
    """Elements between two buses in impedance form (module docstring): sending nodes `p`,
    receiving nodes `s`; `c_p` (m, |p|), `c_s` (m, |s|), `z` (m, m), shunts `y_p`, `y_s`
    (p.u.)."""

    name: str
    p: np.ndarray
    s: np.ndarray
    c_p: np.ndarray
    c_s: np.ndarray
    z: np.ndarray
    y_p: np.ndarray
    y_s: np.ndarray


class _Gram:
    """The real unknowns x of every lifted block: per block of size k, Re G_ij (i ≤ j) and
    Im G_ij (i < j); `form(b, m)` maps a complex coefficient matrix M to the sparse rows of
    Re and Im of Σ M_ij G_ij."""

    def __init__(self) -> None:
        self.sizes: list[int] = []
        self.offsets: list[int] = []
        self.size = 0

    def add(self, k: int) -> int:
        self.sizes.append(k)
        self.offsets.append(self.size)
        self.size += k * k  # k(k+1)/2 real parts and k(k−1)/2 imaginary parts
        return len(self.sizes) - 1

    def _index(self, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k, k) indices of Re G_ij, of Im G_ij and the sign of Im (−1 below the diagonal, 0 on it)."""
        k, off = self.sizes[b], self.offsets[b]
        iu = np.triu_indices(k)
        re = np.zeros((k, k), dtype=int)
        re[iu] = off + np.arange(iu[0].size)
        re = np.triu(re) + np.triu(re, 1).T
        il = np.triu_indices(k, 1)
        im = np.zeros((k, k), dtype=int)
        im[il] = off + iu[0].size + np.arange(il[0].size)
        sign = np.zeros((k, k))
        sign[il] = 1.0
        return re, im + im.T, sign - sign.T

    def form(self, b: int, m: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        re, im, sign = self._index(b)
        m = np.asarray(m, dtype=complex)
        cols = np.concatenate([re.ravel(), im.ravel()])
        row_re = sp.csr_matrix(
            (np.concatenate([m.real.ravel(), -(m.imag * sign).ravel()]), (np.zeros(cols.size, int), cols)), shape=(1, self.size)
        )
        row_im = sp.csr_matrix(
            (np.concatenate([m.imag.ravel(), (m.real * sign).ravel()]), (np.zeros(cols.size, int), cols)), shape=(1, self.size)
        )
        return row_re, row_im

    def embedding(self, b: int) -> sp.csr_matrix:
        """(4k², n_x): vec (column-major) of the real embedding [[Re G, −Im G], [Im G, Re G]]."""
        k = self.sizes[b]
        re, im, sign = self._index(b)
        rows, cols, vals = [], [], []
        big = 2 * k
        for r0, c0, idx, coef in ((0, 0, re, 1.0), (k, k, re, 1.0), (0, k, im, -sign), (k, 0, im, sign)):
            r, c = np.meshgrid(np.arange(k) + r0, np.arange(k) + c0, indexing="ij")
            val = np.broadcast_to(coef, (k, k))
            keep = val.ravel() != 0
            rows.append((r + c * big).ravel()[keep])
            cols.append(idx.ravel()[keep])
            vals.append(val.ravel()[keep])
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(big * big, self.size))

    def value(self, b: int, x: np.ndarray) -> np.ndarray:
        re, im, sign = self._index(b)
        return x[re] + 1j * sign * x[im]


def _null(a: np.ndarray) -> np.ndarray:
    return sla.null_space(a, rcond=1e-9) if a.size else np.zeros((a.shape[1], a.shape[1]))


def _incidence(nodes: np.ndarray, conn: str, phases: int, pos: dict[int, int], orientation: int) -> np.ndarray:
    """(phases, |pos|) each core's winding voltage as a combination of the terminal's nodes."""
    out = np.zeros((phases, len(pos)))

    def put(row: int, node: int, value: float) -> None:
        if node != GROUND:
            out[row, pos[node]] += value

    for k in range(phases):
        if phases == 1:
            put(k, nodes[0], 1.0)
            put(k, nodes[1], -1.0)
        elif conn == "wye":
            put(k, nodes[k], 1.0)
            put(k, nodes[phases], -1.0)
        else:
            put(k, nodes[k], 1.0)
            put(k, nodes[(k + orientation) % phases], -1.0)
    return out


def _transformer(name: str, nodes: np.ndarray, y: np.ndarray, conns: tuple[str, str], phases: int) -> _Branch:
    """A two-winding transformer's impedance form fitted to its primitive admittance `y`
    (p.u., in the order of `nodes` (2, conductors)); NetworkError where no fit reproduces it."""
    flat = nodes.ravel()
    keep = flat != GROUND
    y = y[np.ix_(keep, keep)]
    p = np.unique(nodes[0][nodes[0] != GROUND])
    s = np.unique(nodes[1][nodes[1] != GROUND])
    order = np.concatenate([p, s])
    where = {int(n): i for i, n in enumerate(flat[keep].tolist())}
    y = y[np.ix_([where[n] for n in order.tolist()], [where[n] for n in order.tolist()])]
    n_p = p.size
    y_pp, y_ps = y[:n_p, :n_p], y[:n_p, n_p:]
    scale = np.abs(y).max()
    best: tuple[float, _Branch] | None = None
    for o_p in (1, -1):
        for o_s in (1, -1):
            c_p = _incidence(nodes[0], conns[0], phases, {int(n): i for i, n in enumerate(p.tolist())}, o_p)
            c_s = _incidence(nodes[1], conns[1], phases, {int(n): i for i, n in enumerate(s.tolist())}, o_s)
            basis_pp = np.stack([np.outer(c, c).ravel() for c in c_p], axis=1)
            basis_ps = np.stack([-np.outer(a, b).ravel() for a, b in zip(c_p, c_s, strict=True)], axis=1)
            y_core = np.linalg.lstsq(basis_pp.astype(complex), y_pp.ravel(), rcond=None)[0]
            yt = np.linalg.lstsq(basis_ps.astype(complex), y_ps.ravel(), rcond=None)[0]
            ratio = yt / y_core  # real up to round-off; kept complex so the form reproduces OpenDSS's admittance
            c_s_t = c_s * ratio[:, None]
            model = np.block(
                [
                    [c_p.T @ np.diag(y_core) @ c_p, -c_p.T @ np.diag(y_core) @ c_s_t],
                    [-c_s_t.T @ np.diag(y_core) @ c_p, c_s_t.T @ np.diag(y_core) @ c_s_t],
                ]
            )
            resid = y - model
            shunt = np.diag(np.diag(resid))  # OpenDSS's anti-float shunts of delta windings
            err = np.abs(resid - shunt).max() / scale
            branch = _Branch(name, p, s, c_p, c_s_t, np.diag(1.0 / y_core), shunt[:n_p, :n_p], shunt[n_p:, n_p:])
            if best is None or err < best[0]:
                best = (err, branch)
    assert best is not None
    if best[0] > FIT_RTOL:
        raise NetworkError(
            f"{name}: no ideal-ratio-plus-impedance form reproduces its admittance (off by {best[0]:.1e} relative)"
        )
    return best[1]


@formulation(
    "sdp3",
    role="relaxation",
    networks=("unbalanced-radial",),
    serves_problem=True,
    summary="three-phase SDP branch-flow relaxation (Clarabel PSD cones): certified lower bound on radial unbalanced feeders",
)
class ThreePhaseSdp:
    """The SDP relaxation of `net`'s three-phase OPF (module docstring); `solve` bounds one
    snapshot. NetworkError for a meshed feeder or an element the branch-flow form cannot
    hold (more than two terminals, an admittance it does not reproduce)."""

    def __init__(self, net: PhaseNetwork, slack_export: bool = True):
        if net.meshed:
            raise NetworkError(f"{net.name}: the branch-flow SDP relaxation needs a radial feeder; this one is meshed")
        self.net = net
        base = net.node_base_v
        self.s_base = max(float(np.abs(net.load_p_mw + 1j * net.load_q_mvar).sum()), 1e-3)  # MVA
        branches, shunts = self._branches()
        gram = _Gram()
        self._gram = gram
        home: dict[int, tuple[int, np.ndarray]] = {}  # node → (block, row of E mapping ζ to its voltage)
        drawn: dict[int, list] = {}  # node → rows (re, im) of the power the branches draw there

        def add_drawn(node: int, rows: tuple) -> None:
            drawn.setdefault(int(node), []).append(rows)

        eq_rows: list[sp.csr_matrix] = []
        eq_rhs: list[float] = []
        blocks: list[int] = []

        def w_form(a: int, b: int, coef: complex = 1.0) -> tuple[sp.csr_matrix, sp.csr_matrix]:
            """Re, Im of coef·v_a·v_b* (nodes of one bus)."""
            ba, ea = home[a]
            bb, eb = home[b]
            if ba != bb:
                raise NetworkError(f"{net.name}: nodes {net.node_names[a]} and {net.node_names[b]} are not in one block")
            return gram.form(ba, coef * np.outer(ea, eb.conj()))

        self._w_form = w_form
        # the source: EMF e·ξ behind its Thevenin impedance
        src = net.source
        e_pu = src.emf_v / base[src.nodes]
        z_src = np.linalg.inv(np.diag(base[src.nodes]) @ src.y_s @ np.diag(base[src.nodes]) / (self.s_base * 1e6))
        source = _Branch(
            src.name,
            np.array([-2]),
            src.nodes,
            e_pu[:, None],
            np.eye(len(src.nodes)),
            z_src,
            np.zeros((1, 1)),
            np.zeros((len(src.nodes),) * 2),
        )
        ordered = [source, *branches]
        # nodes whose voltage to ground matters: a wye load or DER there, a band to ground, a branch leaving it
        mon_a, mon_b, _ = self._monitored()
        lb_, db_ = net.load_branches, net.der_branches
        grounded = {int(n) for br_ in (lb_, db_) for n in br_.a[br_.b == GROUND]} | {int(n) for n in mon_a[mon_b == GROUND]}
        grounded |= {int(n) for br_ in branches for n in br_.p}
        self._physical: dict[int, np.ndarray] = {}  # block → its coordinates that are not a gauge
        self._p_source: list = []
        self._coords: list[tuple[_Branch, int, np.ndarray, np.ndarray]] = []
        self._ideal: list[_Branch] = []
        self._flows: tuple | None = None
        leaving: dict[int, list[tuple[int, np.ndarray]]] = {}  # node → (block, row) of each current it feeds
        self._arriving: dict[int, tuple[int, np.ndarray]] = {}  # node → (block, row) of the current fed to it
        for br in ordered:
            if _is_ideal(br):  # no block: its receiving nodes are its sending nodes
                for n_s, n_p in zip(br.s.tolist(), br.p.tolist(), strict=True):
                    if n_s in home:
                        raise NetworkError(
                            f"{net.name}: node {net.node_names[n_s]} is fed by two branches (not radial at node level)"
                        )
                    home[n_s] = home[n_p]
                self._ideal.append(br)
                shunts += [(br.p, br.y_p), (br.s, br.y_s)]
                continue
            b, e_s, e_i, free = self._coordinates(br, gram)
            if free and not (set(br.s.tolist()) & grounded):  # a floating winding's common mode: a gauge
                self._physical[b] = np.arange(gram.sizes[b] - free)
            blocks.append(b)
            self._coords.append((br, b, e_s, e_i))
            k = gram.sizes[b]
            n_p = br.p.size
            for i, n in enumerate(br.s.tolist()):
                if n in home:
                    raise NetworkError(f"{net.name}: node {net.node_names[n]} is fed by two branches (not radial at node level)")
                home[n] = (b, e_s[i])
            if br is source:
                r, _ = gram.form(b, np.eye(k)[:1].T @ np.eye(k)[:1])
                eq_rows.append(r)
                eq_rhs.append(1.0)
            else:  # the sending block equals the bus matrix the parent gives
                for i in range(n_p):
                    for j in range(i, n_p):
                        unit = np.zeros((k, k))
                        unit[i, j] = 1.0  # Σ M G = G_ij
                        g_re, g_im = gram.form(b, unit)
                        w_re, w_im = w_form(int(br.p[i]), int(br.p[j]))
                        eq_rows.append(g_re - w_re)
                        eq_rhs.append(0.0)
                        if i != j:
                            eq_rows.append(g_im - w_im)
                            eq_rhs.append(0.0)
                e_p = np.eye(k)[:n_p]
                cur_p = br.c_p.T @ e_i  # current drawn at each sending node
                for i, n in enumerate(br.p.tolist()):
                    leaving.setdefault(n, []).append((b, cur_p[i] + br.y_p[i] @ e_p))
                    m = np.outer(e_p[i], cur_p[i].conj()) + np.outer(e_p[i], (br.y_p[i] @ e_p).conj())
                    add_drawn(n, gram.form(b, m))
            cur_s = br.c_s.T @ e_i  # current delivered at each receiving node
            for i, n in enumerate(br.s.tolist()):
                self._arriving[n] = (b, cur_s[i] - br.y_s[i] @ e_s)
                m = -np.outer(e_s[i], cur_s[i].conj()) + np.outer(e_s[i], (br.y_s[i] @ e_s).conj())
                rows = gram.form(b, m)
                add_drawn(n, rows)
                if br is source:
                    self._p_source.append(rows[0])
        for node_set, y_sh in shunts:
            for i, n in enumerate(node_set.tolist()):
                bn, en = home[n]
                e_set = np.stack([home[int(j)][1] for j in node_set])
                add_drawn(n, gram.form(bn, np.outer(en, (y_sh[i] @ e_set).conj())))
                leaving.setdefault(n, []).append((bn, y_sh[i] @ e_set))
        missing = [net.node_names[n] for n in range(net.n_node) if n not in home and n not in self._eliminated]
        if missing:
            raise NetworkError(f"{net.name}: node(s) {', '.join(missing[:5])} not reached by a branch from the source")
        self._blocks = blocks
        self._source_block, self._z_source = blocks[0], z_src
        self._home = home
        self._leaving = leaving
        self._w_low, self._w_high = self._branch_ranges()
        self._build(drawn, eq_rows, eq_rhs)
        for parameter in self.problem.parameters():  # compiled once here: the form is the parameters' (DPP)
            parameter.value = np.zeros(parameter.shape)
        self.problem.get_problem_data(cp.CLARABEL)

    # ----- the network as branches ---------------------------------------------------
    def _branches(self) -> tuple[list[_Branch], list[tuple[np.ndarray, np.ndarray]]]:
        """The branches in order from the source (each after its parent) and the shunt
        elements (nodes, admittance p.u.) — module docstring."""
        net = self.net
        base = net.node_base_v
        lines = {ln.element: ln for ln in net.lines}
        trafos = {t.element: t for t in net.transformers}
        children: dict[int, list[int]] = {}
        shunts = []
        for idx, e in enumerate(net.elements):
            buses = set(e.buses)
            nodes = e.nodes.ravel()
            live = nodes[nodes != GROUND]
            if len(buses) == 1 or np.unique(net.node_bus[live]).size == 1:
                keep = nodes != GROUND
                y = e.yprim[np.ix_(keep, keep)]
                # fold repeated nodes (a terminal's conductors on the same node) into one
                uniq, inv = np.unique(live, return_inverse=True)
                fold = sp.csr_matrix((np.ones(live.size), (inv, np.arange(live.size))), shape=(uniq.size, live.size)).toarray()
                y = fold @ y @ fold.T
                shunts.append((uniq, np.diag(base[uniq]) @ y @ np.diag(base[uniq]) / (self.s_base * 1e6)))
                continue
            if len(e.buses) != 2:
                raise NetworkError(
                    f"{net.name}: {e.name} has {len(e.buses)} terminals; the branch-flow SDP models two-terminal elements"
                )
            children.setdefault(e.buses[0], []).append(idx)
            children.setdefault(e.buses[1], []).append(idx)
        out: list[_Branch] = []
        seen = {int(net.source.bus)}
        frontier = [int(net.source.bus)]
        while frontier:
            bus = frontier.pop(0)
            by_child: dict[int, list[int]] = {}
            for idx in children.get(bus, []):
                other = [b for b in net.elements[idx].buses if b != bus][0]
                if other not in seen:
                    by_child.setdefault(other, []).append(idx)
            for child, idxs in by_child.items():
                seen.add(child)
                frontier.append(child)
                parts = []
                for idx in idxs:
                    e = net.elements[idx]
                    nodes = e.nodes if e.buses[0] == bus else e.nodes[::-1]
                    y_pu = (
                        np.diag(base[np.maximum(e.nodes.ravel(), 0)])
                        @ e.yprim
                        @ np.diag(base[np.maximum(e.nodes.ravel(), 0)])
                        / (self.s_base * 1e6)
                    )
                    if e.buses[0] != bus:  # reorder the admittance to the flipped terminals
                        c = e.nodes.shape[1]
                        perm = np.concatenate([np.arange(c, 2 * c), np.arange(c)])
                        y_pu = y_pu[np.ix_(perm, perm)]
                    if idx in lines:
                        parts.append(self._line(e.name, nodes, lines[idx]))
                    elif idx in trafos:
                        t = trafos[idx]
                        if len(t.windings) != 2:
                            raise NetworkError(
                                f"{net.name}: {e.name} has {len(t.windings)} windings; the branch-flow SDP models two"
                            )
                        w = t.windings if e.buses[0] == bus else t.windings[::-1]
                        parts.append(_transformer(e.name, nodes, y_pu, (w[0].conn, w[1].conn), t.phases))
                    else:
                        raise NetworkError(
                            f"{net.name}: {e.name} ({e.kind}) joins two buses; the branch-flow SDP models lines and transformers there"
                        )
                out.append(_merge(parts))
        return self._reduced(out, shunts), shunts

    def _reduced(self, branches: list[_Branch], shunts: list[tuple[np.ndarray, np.ndarray]]) -> list[_Branch]:
        """`branches` (in order from the source) with every chain bus eliminated: a bus
        reached by a line and left by exactly one line, on the same nodes and voltage base,
        with no load, DER or shunt element there and no line shunt at it — the two lines
        carry one current, so they are one line of impedance Z₁ + Z₂ (Kron reduction of a
        shunt-free node: exact). Its nodes' band rows and current caps go with it, which only
        loosens the relaxation (module docstring). The eliminated nodes: `self._eliminated`."""
        net = self.net
        attached = {int(n) for br in (net.load_branches, net.der_branches) for n in np.concatenate([br.a, br.b])}
        attached |= {int(n) for nodes, _ in shunts for n in nodes} | {int(n) for n in net.source.nodes} | {GROUND}
        leaving: dict[int, int] = {}
        for br in branches:
            bus = int(net.node_bus[br.p[0]])
            leaving[bus] = leaving.get(bus, 0) + 1
        kept: list[_Branch] = []
        arriving: dict[int, int] = {}  # bus → index in kept of the branch that reaches it
        eliminated: list[int] = []
        for br in branches:
            bus = int(net.node_bus[br.p[0]])
            parent = kept[arriving[bus]] if bus in arriving else None
            if (
                parent is not None
                and leaving[bus] == 1
                and _plain_line(parent)
                and _plain_line(br)
                and sorted(parent.s.tolist()) == sorted(br.p.tolist())
                and not attached & set(br.p.tolist())
            ):
                order = [int(np.flatnonzero(br.p == n)[0]) for n in parent.s.tolist()]  # br's conductors in parent's order
                merged = _Branch(
                    f"{parent.name.split('…')[0]}…{br.name}",
                    parent.p,
                    br.s[order],
                    parent.c_p,
                    parent.c_s,
                    parent.z + br.z[np.ix_(order, order)],
                    parent.y_p,
                    br.y_s[np.ix_(order, order)],
                )
                eliminated += parent.s.tolist()
                at = arriving.pop(bus)
                kept[at] = merged
                arriving[int(net.node_bus[br.s[0]])] = at
                continue
            arriving[int(net.node_bus[br.s[0]])] = len(kept)
            kept.append(br)
        self._eliminated = frozenset(eliminated)
        return kept

    def _line(self, name: str, nodes: np.ndarray, line) -> _Branch:
        """A line's impedance form (p.u.): identity incidences, Z, half its shunt at each end."""
        base = self.net.node_base_v
        p, s = nodes[0], nodes[1]
        if (p == GROUND).any() or (s == GROUND).any():
            raise NetworkError(f"{self.net.name}: {name} has a conductor on ground; the branch-flow SDP needs its nodes")
        z = line.z_ohm * (self.s_base * 1e6) / np.outer(base[p], base[p])
        y_p = line.y_shunt_s / 2 * np.outer(base[p], base[p]) / (self.s_base * 1e6)
        y_s = line.y_shunt_s / 2 * np.outer(base[s], base[s]) / (self.s_base * 1e6)
        ratio = base[s] / base[p]
        eye = np.eye(p.size)
        return _Branch(name, p, s, eye, np.diag(ratio), z, y_p, y_s)

    # ----- the lifted model ------------------------------------------------------------
    @staticmethod
    def _coordinates(br: _Branch, gram: _Gram) -> tuple[int, np.ndarray, np.ndarray, int]:
        """The branch's block, the maps from its coordinates ζ to the receiving voltages
        (E_s) and the currents (E_I) (module docstring), and how many of ζ's last
        coordinates are receiving voltages the relation leaves free (a delta winding's
        common mode)."""
        m, n_p = br.z.shape[0], br.p.size
        left = _null(br.c_s.T)  # ℓ with ℓᵀ·C_s = 0: the relation's own constraints
        lz = left.T @ br.z
        free_i = _null(lz) if left.size else np.eye(m)
        fixed_i = np.linalg.pinv(lz) @ left.T @ br.c_p if left.size else np.zeros((m, n_p))
        free_s = _null(br.c_s)
        pinv = np.linalg.pinv(br.c_s)
        r, g = free_i.shape[1], free_s.shape[1]
        e_i = np.hstack([fixed_i, free_i, np.zeros((m, g))])
        e_s = np.hstack([pinv @ (br.c_p - br.z @ fixed_i), -pinv @ br.z @ free_i, free_s])
        return gram.add(n_p + r + g), e_s, e_i, g

    def _build(self, drawn: dict[int, list], eq_rows: list, eq_rhs: list) -> None:
        net, gram = self.net, self._gram
        n = net.n_node
        s_base = self.s_base
        lb, db = net.load_branches, net.der_branches
        # lifted delta / neutral branches: a block (v_a, v_b, i) each, its voltage part the bus's
        lifted: dict[tuple[str, int], int] = {}
        for kind, br in (("load", lb), ("der", db)):
            for j in np.flatnonzero(br.b != GROUND).tolist():
                a, bnode = int(br.a[j]), int(br.b[j])
                blk = gram.add(3)
                lifted[(kind, j)] = blk
                self._blocks.append(blk)
                for r_i, r_j, u, v in ((0, 0, a, a), (0, 1, a, bnode), (1, 1, bnode, bnode)):
                    unit = np.zeros((3, 3))
                    unit[r_i, r_j] = 1.0
                    g_re, g_im = gram.form(blk, unit)
                    w_re, w_im = self._w_form(u, v)
                    eq_rows.append(_pad(g_re, gram.size) - _pad(w_re, gram.size))
                    eq_rhs.append(0.0)
                    if r_i != r_j:
                        eq_rows.append(_pad(g_im, gram.size) - _pad(w_im, gram.size))
                        eq_rhs.append(0.0)
        size = gram.size
        x = cp.Variable(size, name="g")
        self._x = x

        def pad(m: sp.csr_matrix) -> sp.csr_matrix:
            return _pad(m, size)

        self.load_p = cp.Parameter(net.n_load, name="load_p")
        self.load_q = cp.Parameter(net.n_load, name="load_q")
        self.der_p = cp.Parameter(len(net.ders), name="der_p")
        self.q_limit = cp.Parameter(len(net.ders), nonneg=True, name="q_limit")
        q = self.q = cp.Variable(len(net.ders), name="q")
        constraints: list[cp.Constraint] = [cp.abs(q) <= self.q_limit]
        constraints.append(sp.vstack([pad(r) for r in eq_rows]).tocsr() @ x == np.array(eq_rhs))
        kcl = self._kcl_caps(lifted)
        self.kcl_cap = cp.Parameter(len(kcl), nonneg=True, name="kcl_cap")
        if kcl:
            constraints.append(sp.vstack([pad(r) for r in kcl]).tocsr() @ x <= self.kcl_cap)
        # what the branches draw at every node (p.u.)
        empty = sp.csr_matrix((1, size))
        draw_p = sp.vstack([sum((pad(r[0]) for r in drawn.get(node, [])), empty) for node in range(n)]).tocsr()
        draw_q = sp.vstack([sum((pad(r[1]) for r in drawn.get(node, [])), empty) for node in range(n)]).tocsr()
        balance_p: list = [draw_p @ x]
        balance_q: list = [draw_q @ x]
        if self._ideal:  # each ideal branch's conductors carry a power f from p to s
            ends_p = np.concatenate([br.p for br in self._ideal])
            ends_s = np.concatenate([br.s for br in self._ideal])
            cols = np.arange(ends_p.size)
            through = sp.csr_matrix((np.ones(cols.size), (ends_p, cols)), shape=(n, cols.size)) - sp.csr_matrix(
                (np.ones(cols.size), (ends_s, cols)), shape=(n, cols.size)
            )
            f_p, f_q = cp.Variable(cols.size, name="f_p"), cp.Variable(cols.size, name="f_q")
            balance_p.append(through @ f_p)
            balance_q.append(through @ f_q)
            self._flows = (f_p, f_q, through)
        # load and DER branches: drawn power (p.u.; a DER draws minus what it injects)
        s_p, s_q = self._load_factors(self._pair_w(lb.a, lb.b, lb.vbase_v), constraints)
        load_dp = cp.multiply(lb.share / s_base, cp.multiply(self.load_p[lb.owner], s_p))
        load_dq = cp.multiply(lb.share / s_base, cp.multiply(self.load_q[lb.owner], s_q))
        der_dp = -cp.multiply(db.share / s_base, self.der_p[db.owner]) if db.n else cp.Constant(np.zeros(0))
        der_dq = -cp.multiply(db.share / s_base, q[db.owner]) if db.n else cp.Constant(np.zeros(0))
        cap_rows: list[sp.csr_matrix] = []
        cap_of: list[tuple[str, int]] = []
        for kind, br, dp, dq in (("load", lb, load_dp, load_dq), ("der", db, der_dp, der_dq)):
            if not br.n:
                continue
            wye = np.flatnonzero(br.b == GROUND)
            at_a = sp.csr_matrix((np.ones(wye.size), (br.a[wye], np.arange(wye.size))), shape=(n, wye.size))
            balance_p.append(at_a @ dp[wye])
            balance_q.append(at_a @ dq[wye])
            for j in np.flatnonzero(br.b != GROUND).tolist():
                blk = lifted[(kind, j)]
                xa = [pad(r) @ x for r in gram.form(blk, np.outer(np.eye(3)[0], np.eye(3)[2]))]  # v_a·i*
                xb = [pad(r) @ x for r in gram.form(blk, np.outer(np.eye(3)[1], np.eye(3)[2]))]  # v_b·i*
                # the branch draws S = v_a·i* − v_b·i*: v_a·i* at node a, −v_b·i* at node b
                constraints += [xa[0] - xb[0] == dp[j], xa[1] - xb[1] == dq[j]]
                if self._capped(kind, j):  # |i|² ≤ max |S|²·c²/w (valid at every point)
                    cap_rows.append(pad(gram.form(blk, np.outer(np.eye(3)[2], np.eye(3)[2]))[0]))
                    cap_of.append((kind, j))
                for node, part, sign in ((int(br.a[j]), xa, 1.0), (int(br.b[j]), xb, -1.0)):
                    onehot = np.zeros(n)
                    onehot[node] = sign
                    balance_p.append(onehot * part[0])
                    balance_q.append(onehot * part[1])
        self._balance = (sum(balance_p), sum(balance_q))
        constraints += [self._balance[0] == 0, self._balance[1] == 0]
        self._cap_of = cap_of
        self.current_cap = cp.Parameter(len(cap_of), nonneg=True, name="current_cap")
        if cap_of:
            constraints.append(sp.vstack(cap_rows).tocsr() @ x <= self.current_cap)
        if db.n:
            constraints.append(self._pair_w(db.a, db.b, db.vbase_v) >= DER_VMIN_PU**2)
        mon_a, mon_b, base_m = self._monitored()
        lo, hi = net.band
        w_mon = self._pair_w(mon_a, mon_b, base_m)
        constraints += [w_mon >= lo**2, w_mon <= hi**2]
        for blk in self._blocks:
            k = gram.sizes[blk]
            constraints.append(cp.reshape(gram.embedding(blk) @ x, (2 * k, 2 * k), order="F") >> 0)
        # losses = P delivered by the source − loads + DER = (node balance summed) what every
        # branch and shunt but the source draws: Σ Re tr(R·L) + shunt losses, a sum of small
        # positive terms rather than a difference of large ones
        inside = sp.csr_matrix(draw_p.sum(axis=0)) - sum(pad(r) for r in self._p_source)
        losses = KW_PER_MW * s_base * (inside @ x)[0]
        self.problem = cp.Problem(cp.Minimize(losses), constraints)

    def _monitored(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`net.monitored`'s pairs (a, b, base V) but those on an eliminated node (`_reduced`)."""
        a, b, base_v, _ = self.net.monitored
        keep = np.array([int(i) not in self._eliminated and int(j) not in self._eliminated for i, j in zip(a, b, strict=True)])
        return a[keep], b[keep], base_v[keep]

    def _pair_w(self, a: np.ndarray, b: np.ndarray, base_v: np.ndarray) -> cp.Expression:
        """|v_a − v_b|²/base² (b GROUND: |v_a|²) for each pair, linear in the lifted blocks."""
        node_base = self.net.node_base_v
        rows = []
        for i, j, bv in zip(a.tolist(), b.tolist(), base_v.tolist(), strict=True):
            ci = node_base[i] / bv
            row = ci**2 * self._w_form(i, i)[0]
            if j != GROUND:
                cj = node_base[j] / bv
                row = row + cj**2 * self._w_form(j, j)[0] - 2 * ci * cj * self._w_form(i, j)[0]
            rows.append(_pad(row, self._gram.size))
        if not rows:
            return cp.Constant(np.zeros(0))
        return sp.vstack(rows).tocsr() @ self._x

    def _kcl_caps(self, lifted: dict[tuple[str, int], int]) -> list[sp.csr_matrix]:
        """Rows r with r·x ≤ `kcl_cap`: at each node, the lifted |current fed to it|² at
        most k·Σ of the |·|² of the k currents it passes on — lifted for branches and shunts,
        `current_caps` for wye loads and DER (Kirchhoff's current law and Cauchy–Schwarz,
        valid at every operating point). They bound every branch's current block from the
        leaves up: a near-lossless regulator's or the source's current (whose Thevenin
        losses are in no objective term, as in the exact model) is otherwise free, and
        Clarabel's interior point inflates it until mutual impedances shift power between
        phases. A node that feeds an ideal branch or an uncapped load gets no row."""
        net, gram = self.net, self._gram
        lb, db = net.load_branches, net.der_branches
        wye_at: dict[int, list[tuple[str, int]]] = {}
        lifted_at: dict[int, list[int]] = {}
        for kind, br in (("load", lb), ("der", db)):
            for j in range(br.n):
                if br.b[j] == GROUND:
                    wye_at.setdefault(int(br.a[j]), []).append((kind, j))
                else:
                    for node in (int(br.a[j]), int(br.b[j])):
                        lifted_at.setdefault(node, []).append(lifted[(kind, j)])
        ideal_from = {int(n) for br in self._ideal for n in br.p}
        rows: list[sp.csr_matrix] = []
        self._kcl_wye: list[tuple[int, list[tuple[str, int]]]] = []
        corner = np.outer(np.eye(3)[2], np.eye(3)[2])
        for n, (b, a) in self._arriving.items():
            wyes = wye_at.get(n, [])
            terms = self._leaving.get(n, [])
            blocks = lifted_at.get(n, [])
            k = len(terms) + len(wyes) + len(blocks)
            if n in ideal_from or k == 0 or not all(self._capped(kind, j) for kind, j in wyes):
                continue
            row = _pad(gram.form(b, np.outer(a, a.conj()))[0], gram.size)
            for tb, ta in terms:
                row = row - k * _pad(gram.form(tb, np.outer(ta, ta.conj()))[0], gram.size)
            for blk in blocks:
                row = row - k * _pad(gram.form(blk, corner)[0], gram.size)
            rows.append(row)
            self._kcl_wye.append((k, wyes))
        return rows

    def _branch_ranges(self) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Per load and DER branch the lower bound on w = u² the model keeps (the band on a
        monitored pair, a switching load's vminpu, a DER's DER_VMIN_PU; NaN where none),
        and per load branch the upper bound (`_range`) — what caps a lifted current."""
        net = self.net
        lo = net.band[0]
        a, b, base_m, _ = net.monitored
        low = {(int(i), int(j)): (lo * bm) ** 2 for i, j, bm in zip(a, b, base_m, strict=True)}
        out = {}
        for kind, br in (("load", net.load_branches), ("der", net.der_branches)):
            out[kind] = np.array(
                [low.get((int(i), int(j)), np.nan) / v**2 for i, j, v in zip(br.a, br.b, br.vbase_v, strict=True)]
            )
        lm, owner = net.load_models, net.load_branches.owner
        out["load"] = np.where(lm.model[owner] != CONSTANT_Z, np.fmax(out["load"], lm.vminpu[owner] ** 2), out["load"])
        out["der"] = np.fmax(out["der"], DER_VMIN_PU**2)
        return out, self._range()

    def _capped(self, kind: str, j: int) -> bool:
        """Whether the branch's current has a cap (`current_caps`) whatever the data."""
        if kind == "der":
            return True
        n_load = self.net.n_load
        return bool(self._load_worst(np.ones(n_load), np.ones(n_load))[j] < 1e6)

    def _load_worst(self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray) -> np.ndarray:
        """Per load branch the largest |S|²/w over w's range (MVA² p.u.; inf, or above 1e12
        per unit power, where unbounded)."""
        lb = self.net.load_branches
        worst = np.zeros(lb.n)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for w in (np.nan_to_num(self._w_low["load"], nan=1e-12), self._w_high):  # no lower bound: w → 0
                s_p, s_q = self._law(w)
                val = ((load_p_mw[lb.owner] * s_p) ** 2 + (load_q_mvar[lb.owner] * s_q) ** 2) / w
                worst = np.maximum(worst, np.where(np.isnan(val), np.inf, val))
        return lb.share**2 * worst

    def _law(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each load branch's factors s_P, s_Q at w (its law; PQ above vmaxpu: w/vmaxpu²)."""
        lm, owner = self.net.load_models, self.net.load_branches.owner
        model = lm.model[owner]
        out = []
        for cvr in (lm.cvr_p[owner], lm.cvr_q[owner]):
            e = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], cvr) / 2
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                out.append(np.where(model == CONSTANT_PQ, np.maximum(1.0, w / lm.vmaxpu[owner] ** 2), w**e))
        return out[0], out[1]

    def branch_caps(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Per load and DER branch the cap on |i|² (p.u., inf where none): |S|²·c²/w at the
        worst end of w's range (|S|²/w is monotone in w on each law's piece), c = node base
        / branch base; a DER: (P² + Q̄²)·c²/w_low."""
        net = self.net
        lb, db = net.load_branches, net.der_branches
        with np.errstate(invalid="ignore", divide="ignore"):
            s_der = db.share**2 * (der_p_mw[db.owner] ** 2 + q_limit_mvar[db.owner] ** 2) / self._w_low["der"]
        out = {}
        for kind, br, mag in (("load", lb, self._load_worst(load_p_mw, load_q_mvar)), ("der", db, s_der)):
            c = net.node_base_v[br.a] / br.vbase_v
            out[kind] = mag * c**2 / self.s_base**2
        return out

    def current_caps(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> np.ndarray:
        """The caps of the lifted branches' |i|² (`branch_caps`), in `current_cap`'s order."""
        caps = self.branch_caps(load_p_mw, load_q_mvar, der_p_mw, q_limit_mvar)
        return np.array([caps[kind][j] for kind, j in self._cap_of])

    def kcl_caps(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> np.ndarray:
        """`kcl_cap`'s values: k·Σ of the caps of the wye branches at each row's node."""
        caps = self.branch_caps(load_p_mw, load_q_mvar, der_p_mw, q_limit_mvar)
        return np.array([k * sum(caps[kind][j] for kind, j in wyes) for k, wyes in self._kcl_wye])

    def _range(self) -> np.ndarray:
        """(n_load_branch,) the upper bound the band gives on each load branch's w: its own
        where the branch is a monitored pair, else by the triangle inequality from its nodes'
        phase-to-ground limits (|v_a − v_b| ≤ |v_a| + |v_b|); inf where neither applies."""
        net = self.net
        lb = net.load_branches
        a, b, base_m, _ = net.monitored
        hi = net.band[1]
        bound = {(int(i), int(j)): (hi * bm) ** 2 for i, j, bm in zip(a, b, base_m, strict=True)}
        node_hi = np.full(net.n_node + 1, np.inf)  # V; the last entry is ground
        node_hi[-1] = 0.0
        to_ground = b == GROUND
        node_hi[a[to_ground]] = hi * base_m[to_ground]
        triangle = (node_hi[lb.a] + node_hi[np.where(lb.b == GROUND, -1, lb.b)]) ** 2
        own = np.array([bound.get((int(i), int(j)), np.inf) for i, j in zip(lb.a, lb.b, strict=True)])
        return np.fmin(own, triangle) / lb.vbase_v**2

    def _load_factors(self, w: cp.Expression, constraints: list) -> tuple[cp.Expression, cp.Expression]:
        """The factors s_P, s_Q of each load branch's nominal power (module docstring), their
        hull constraints appended to `constraints`."""
        net = self.net
        lm, owner = net.load_models, net.load_branches.owner
        model = lm.model[owner]
        vmin, vmax = lm.vminpu[owner], lm.vmaxpu[owner]
        w_hi = self._range()
        n_br = len(owner)
        switching = np.flatnonzero(model != CONSTANT_Z)
        if switching.size:
            constraints.append(w[switching] >= vmin[switching] ** 2)
        bounded = np.flatnonzero((model == CONSTANT_I) | (model == EXPONENTIAL))
        if bounded.size:
            constraints.append(w[bounded] <= vmax[bounded] ** 2)
        factors = []
        for which, cvr in (("p", lm.cvr_p[owner]), ("q", lm.cvr_q[owner])):
            exponent = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], cvr) / 2
            s = cp.Variable(n_br, name=f"s_{which}")
            linear = np.flatnonzero(exponent == 1.0)
            if linear.size:
                constraints.append(s[linear] == w[linear])
            pq = np.flatnonzero((model == CONSTANT_PQ) & (exponent == 0.0))
            if pq.size:  # max(1, w/vmax²) and its chord where w is bounded
                constraints += [s[pq] >= 1.0, s[pq] >= cp.multiply(1.0 / vmax[pq] ** 2, w[pq])]
                lo_w, hi_w = vmin[pq] ** 2, w_hi[pq]
                fin = np.isfinite(hi_w)
                if fin.any():
                    idx, lo_f, hi_f = pq[fin], lo_w[fin], hi_w[fin]
                    g_lo, g_hi = np.maximum(1.0, lo_f / vmax[idx] ** 2), np.maximum(1.0, hi_f / vmax[idx] ** 2)
                    slope = (g_hi - g_lo) / np.maximum(hi_f - lo_f, 1e-12)
                    constraints.append(s[idx] <= g_lo + cp.multiply(slope, w[idx] - lo_f))
            for e in sorted(set(exponent[(exponent != 1.0) & (model != CONSTANT_PQ)].tolist())):
                idx = np.flatnonzero((exponent == e) & (model != CONSTANT_PQ))
                lo_w, hi_w = vmin[idx] ** 2, vmax[idx] ** 2
                chord = lo_w**e + cp.multiply((hi_w**e - lo_w**e) / (hi_w - lo_w), w[idx] - lo_w)
                if e == 0.0:
                    constraints.append(s[idx] == 1.0)
                elif e < 1.0:  # concave: between the chord and the curve
                    constraints += [s[idx] >= chord, cp.power(w[idx], e) >= s[idx]]
                else:
                    constraints += [s[idx] <= chord, cp.power(w[idx], e) <= s[idx]]
            factors.append(s)
        return factors[0], factors[1]

    # ----- solving -----------------------------------------------------------------------
    def rank_ratios(self) -> np.ndarray:
        """Per block at the last solution, its second-to-first eigenvalue ratio. The source's
        block (ξ, I) is measured by what its rank can change in the network instead: its
        current block L is in no objective term (the Thevenin losses are excluded, as in the
        exact model) and only capped (`_kcl_caps`), so an interior-point solution inflates
        it within the cap; only Z·(L − I·Iᴴ)·Zᴴ reaches the source bus's voltages — its norm
        relative to theirs. A floating winding's common mode (`_coordinates`' free receiving
        voltage, at a bus with no wye load or DER, no band to ground and no branch leaving
        it: ieee123's xfm1) is left out of its block: it changes nothing but the draw of the
        winding's anti-float shunts (1e-8 p.u.), and an interior-point solution inflates it."""
        x = self._x.value
        if x is None:
            raise RuntimeError("rank_ratios needs a solution")
        out: list[float] = []
        for blk in self._blocks:
            g = self._gram.value(blk, x)
            if blk == self._source_block:
                _, _, e_s, e_i = self._coords[0]
                cur = g[1:, 0] / g[0, 0].real
                excess = self._z_source @ (g[1:, 1:] - np.outer(cur, cur.conj())) @ self._z_source.conj().T
                out.append(float(np.linalg.norm(excess, 2) / np.linalg.norm(e_s @ g @ e_s.conj().T, 2)))
                continue
            if blk in self._physical:  # the common mode of a floating winding changes nothing: left out
                keep = self._physical[blk]
                g = g[np.ix_(keep, keep)]
            eig = np.linalg.eigvalsh(g)[::-1]
            out.append(float(eig[1] / max(eig[0], 1e-300)) if eig.size > 1 else 0.0)
        return np.array(out)

    def _snapshot(self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray) -> None:
        """The parameters at one snapshot (`solve`'s arguments), the caps derived from them."""
        self.load_p.value = np.asarray(load_p_mw, dtype=float)
        self.load_q.value = np.asarray(load_q_mvar, dtype=float)
        self.der_p.value = np.asarray(der_p_mw, dtype=float)
        self.q_limit.value = np.maximum(np.asarray(q_limit_mvar, dtype=float), 0.0)
        data = (self.load_p.value, self.load_q.value, self.der_p.value, self.q_limit.value)
        self.current_cap.value = self.current_caps(*data)
        self.kcl_cap.value = self.kcl_caps(*data)

    def lift(
        self,
        v: np.ndarray,
        load_p_mw: np.ndarray,
        load_q_mvar: np.ndarray,
        der_p_mw: np.ndarray,
        q_limit_mvar: np.ndarray,
        q_mvar: np.ndarray,
    ) -> None:
        """Set the snapshot (`solve`'s arguments) and the relaxation's unknowns to the
        operating point with node voltages `v` (n_node,) V and DER Q `q_mvar` (n_der,): each
        block the Gram matrix ζζᴴ of its coordinates (solved from the voltages and the
        branch currents), the load factors at the power flow's law, the ideal branches'
        flows from the balance. A rank-one point: `problem.objective.value` is then its
        losses less what the ideal branches dissipate (module docstring), every constraint
        met where the point is the power flow's and within the band."""
        self._snapshot(load_p_mw, load_q_mvar, der_p_mw, q_limit_mvar)
        net, gram = self.net, self._gram
        vpu = np.asarray(v) / net.node_base_v
        x = np.zeros(gram.size)

        def put(blk: int, zeta: np.ndarray) -> None:
            re, im, sign = gram._index(blk)
            g = np.outer(zeta, zeta.conj())
            x[re] = g.real
            x[im[sign > 0]] = g.imag[sign > 0]

        for br, blk, e_s, e_i in self._coords:
            vp = np.ones(1, complex) if blk == self._source_block else vpu[br.p]
            current = np.linalg.solve(br.z, br.c_p @ vp - br.c_s @ vpu[br.s])
            maps = np.vstack([np.eye(gram.sizes[blk])[: br.p.size], e_s, e_i])
            put(blk, np.linalg.lstsq(maps, np.concatenate([vp, vpu[br.s], current]), rcond=None)[0])
        exp_p, exp_q, cap = load_law(net)
        lb, db = net.load_branches, net.der_branches
        vz = np.append(vpu * net.node_base_v, 0.0)
        u = np.abs(vz[lb.a] - vz[np.where(lb.b == GROUND, -1, lb.b)]) / lb.vbase_v
        s_p, s_q = (u**2 * np.minimum(u, cap) ** (e - 2.0) for e in (exp_p, exp_q))  # the power flow's law
        p_load, q_load = np.asarray(load_p_mw, dtype=float), np.asarray(load_q_mvar, dtype=float)
        drawn = lb.share * (p_load[lb.owner] * s_p + 1j * q_load[lb.owner] * s_q) / self.s_base
        q = np.asarray(q_mvar, dtype=float)
        injected = db.share * (np.asarray(der_p_mw, dtype=float)[db.owner] + 1j * q[db.owner]) / self.s_base
        lifted = iter(self._blocks[len(self._coords) :])
        for ends, power in ((lb, drawn), (db, -injected)):
            for j in np.flatnonzero(ends.b != GROUND):
                a, b = ends.a[j], ends.b[j]
                put(next(lifted), np.array([vpu[a], vpu[b], np.conj(power[j] / (vpu[a] - vpu[b]))]))
        for var in self.problem.variables():
            values = {"s_p": s_p, "s_q": s_q, "q": q}
            if var.name() in values:
                var.value = values[var.name()]
        self._x.value = x
        if self._flows is not None:  # an ideal branch carries what its receiving side draws
            f_p, f_q, through = self._flows
            for f, balance in ((f_p, self._balance[0]), (f_q, self._balance[1])):
                f.value = np.zeros(f.size)
                f.value = np.linalg.lstsq(through.toarray(), -balance.value, rcond=None)[0]

    def solve(self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray) -> BoundSolve:
        """One snapshot's bound: loads' P and Q (n_load,) at their law's reference, DER P and
        usable |Q| (n_der,), MW/MVAr."""
        self._snapshot(load_p_mw, load_q_mvar, der_p_mw, q_limit_mvar)
        start = time.perf_counter()
        for options in CLARABEL_ATTEMPTS:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # cvxpy's "inaccurate": the status says it
                    self.problem.solve(solver=cp.CLARABEL, **options)
                status = str(self.problem.status)
            except cp.error.SolverError:
                status = "solver_error"
            if status in (cp.OPTIMAL, cp.INFEASIBLE):
                break
        ms = (time.perf_counter() - start) * 1e3
        if status != cp.OPTIMAL:
            return BoundSolve(np.nan, np.nan, False, status == cp.INFEASIBLE, status, ms, np.full(len(self.net.ders), np.nan))
        ratio = float(self.rank_ratios().max())
        q = np.array(self.q.value, dtype=float)
        return BoundSolve(float(self.problem.value), ratio, ratio <= RANK_RATIO, False, status, ms, q)


def _is_ideal(br: _Branch) -> bool:
    """A line whose impedance is below Z_IDEAL on equal bases at both ends (a switch)."""
    square = br.c_p.shape == br.c_s.shape and br.c_p.shape[0] == br.c_p.shape[1]
    return bool(
        square and np.allclose(br.c_p, np.eye(br.p.size)) and np.allclose(br.c_s, br.c_p) and np.abs(br.z).max() < Z_IDEAL
    )


def _plain_line(br: _Branch) -> bool:
    """A shunt-free line on equal voltage bases (identity incidences), a chain's link."""
    eye = np.eye(br.p.size)
    return bool(
        br.c_p.shape == br.c_s.shape == eye.shape
        and np.array_equal(br.c_p, eye)
        and np.array_equal(br.c_s, eye)
        and not br.y_p.any()
        and not br.y_s.any()
    )


def _pad(m: sp.csr_matrix, width: int) -> sp.csr_matrix:
    """`m` widened to `width` columns (rows built before later blocks were added)."""
    m = sp.csr_matrix(m)
    return sp.csr_matrix((m.data, m.indices, m.indptr), shape=(m.shape[0], width))


def _merge(parts: list[_Branch]) -> _Branch:
    """Elements in parallel between the same two buses as one branch (cores stacked)."""
    if len(parts) == 1:
        return parts[0]
    p = np.unique(np.concatenate([b.p for b in parts]))
    s = np.unique(np.concatenate([b.s for b in parts]))
    pos_p = {int(n): i for i, n in enumerate(p.tolist())}
    pos_s = {int(n): i for i, n in enumerate(s.tolist())}

    def widen(mat: np.ndarray, nodes: np.ndarray, pos: dict[int, int], width: int) -> np.ndarray:
        out = np.zeros((mat.shape[0], width), dtype=mat.dtype)
        out[:, [pos[int(n)] for n in nodes]] = mat
        return out

    def square(mat: np.ndarray, nodes: np.ndarray, pos: dict[int, int], width: int) -> np.ndarray:
        out = np.zeros((width, width), dtype=complex)
        idx = [pos[int(n)] for n in nodes]
        out[np.ix_(idx, idx)] = mat
        return out

    return _Branch(
        "+".join(b.name for b in parts),
        p,
        s,
        np.vstack([widen(b.c_p, b.p, pos_p, p.size) for b in parts]),
        np.vstack([widen(b.c_s, b.s, pos_s, s.size) for b in parts]),
        sla.block_diag(*[b.z for b in parts]),
        np.sum([square(b.y_p, b.p, pos_p, p.size) for b in parts], axis=0),
        np.sum([square(b.y_s, b.s, pos_s, s.size) for b in parts], axis=0),
    )
