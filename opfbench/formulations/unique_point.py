"""Where no DER has a decision (every usable |Q| is 0 and nothing may curtail: the night at
k = 0, every step at k = 1), the three-phase OPF's feasible set is the set of the power
flow's solutions that meet the exact model's constraints. This module proves, where it can,
that the set holds at most one point — then the power flow's point, where it meets those
constraints, IS the optimum, and its losses are the optimum's value: a certificate that
needs no relaxation (the SDP's own accuracy, ~1e-5 of the losses on eulv, cannot certify a
night whose losses are a few watts).

The network equations (`powerflow.multiphase`, at fixed taps): Y·V = I_source + I_br(V),
I_br the currents the load branches draw (taken out of node a, into node b) and the DER
branches inject (I = conj(S/d), S fixed). Two solutions V, V′ give ΔV = Z·ΔI_br, Z = Y⁻¹
(Y holds the source's admittance; where its LU finds it singular, no certificate). Branch l sees d_l = V_a − V_b; a load
draws i = conj(S(u)/d), S(u) = P·s_P(u) + j·Q·s_Q(u) its law at u = |d|/V_base. Where
every branch's |d| lies in [ρ_l, σ_l] (V),

    i − i′ = conj(S(u))·(1/d̄ − 1/d̄′) + conj(S(u) − S(u′))/d̄′,
    |i − i′| ≤ K_l·|d − d′|,   K_l = S_max/ρ² + L_S/(V_base·ρ),

S_max and L_S the largest |S| and |dS/du| over u ∈ [ρ, σ]/V_base, bounded by the P and Q
parts separately: each part is u^e up to the law's cap (vmaxpu for constant PQ and |I|,
`ac_three_phase.load_law`) and u²·cap^(e−2) above it, and on each piece a power of u and
its derivative are monotone, so their extremes lie at the piece's ends. A constant-
impedance branch draws conj(S₀)·d/V_base²: K = |S₀|/V_base² exactly, whatever ρ and σ; a
DER branch (S fixed): K = |S|/ρ². In p.u. of each node's base (x = V/base) and on the
nodes the branches touch (set N),

    |Δx_i| ≤ Σ_l |Z_ia − Z_ib|·K_l·(base_a + base_b)/base_i · ‖Δx_N‖∞    (base_b = 0 at ground)

so where the largest such row sum, the contraction factor `L`, is below 1, Δx_N = 0, the
branch currents agree, and ΔV = Z·0 = 0: at most one solution. `CONTRACTION_MAX` asks for
a margin below 1 that the round-off of Z (one sparse LU) cannot cross.

The region: the exact model's constraints (`models.ac_three_phase`), each widened by
`three_phase.BAND_TOL` (the tolerance an accepted point has): the band on the monitored
voltages, a switching load's u ≥ vminpu, a constant-|I| or exponential load's u ≤ vmaxpu,
a DER branch's u ≥ DER_VMIN_PU. A branch's ρ and σ come from the rows that bound its own
voltage: its monitored pair (a, b) and its own rows, and above, where its nodes' voltages
to ground are monitored, |v_a − v_b| ≤ |v_a| + |v_b| (a delta branch); a branch that is not a constant
impedance and has no such lower bound (or, with a law growing in u, no upper one) has
K = inf — no certificate. The OPF's feasible set lies in that region, so where L <
CONTRACTION_MAX and the power flow's point meets every constraint, the point is the
OPF's only feasible point.

Units: MW, MVAr (load P and Q at their law's reference, DER power generated), V, A, Ω.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from opfbench.formulations.models.ac_three_phase import DER_VMIN_PU, load_law
from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_Z, EXPONENTIAL
from opfbench.powerflow.multiphase import PhaseFlowResult
from opfbench.powerflow.sparse import factorize

CONTRACTION_MAX = 0.9
"""The contraction factor must stay below this (the proof needs < 1; the margin covers the
round-off of the impedances Z = Y⁻¹ it is computed from, relative errors of the order of
Y's condition number times machine ε — far below 0.1 on the shipped feeders, ieee13's
near-ideal regulators included)."""
_CHUNK = 256  # right-hand sides per sparse solve when forming Z's columns


@lru_cache(maxsize=8)
def _reach(net: PhaseNetwork, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per network: M (|N|, n_load_branch + n_der_branch) the coefficients |Z_ia − Z_ib|·
    (base_a + base_b)/base_i (module docstring; NaN where Z is not finite), and per branch
    (loads, then DER) ρ and σ (V, 0 and inf where no row bounds it), and the nodes N."""
    lb, db = net.load_branches, net.der_branches
    a = np.concatenate([lb.a, db.a])
    b = np.concatenate([lb.b, db.b])
    nodes = np.unique(np.concatenate([a, b[b != GROUND]]))
    pos = np.full(net.n_node + 1, len(nodes))  # GROUND (−1) → the zero column
    pos[nodes] = np.arange(len(nodes))
    z = np.zeros((len(nodes), len(nodes) + 1), dtype=complex)
    try:
        lu = factorize(net.ybus)
    except RuntimeError:  # singular (a floating island): no Z, no certificate
        z[:] = np.nan
        lu = None
    for start in range(0, len(nodes) if lu is not None else 0, _CHUNK):
        cols = nodes[start : start + _CHUNK]
        rhs = np.zeros((net.n_node, len(cols)), dtype=complex, order="F")
        rhs[cols, np.arange(len(cols))] = 1.0
        z[:, start : start + len(cols)] = lu.solve(rhs)[nodes]
    base = np.append(net.node_base_v, 0.0)
    reach = np.abs(z[:, pos[a]] - z[:, pos[b]]) * (base[a] + base[b])[None, :] / net.node_base_v[nodes][:, None]
    # each branch's |d| range (V) from the rows that bound it
    lo, hi = net.band
    mon_a, mon_b, mon_base, _ = net.monitored
    pair = {(int(i), int(j)): float(v) for i, j, v in zip(mon_a, mon_b, mon_base, strict=True)}
    at_pair = np.array([pair.get((int(i), int(j)), np.nan) for i, j in zip(a, b, strict=True)])
    rho = np.where(np.isfinite(at_pair), (lo - tol) * at_pair, 0.0)
    node_hi = np.full(net.n_node + 1, np.inf)  # V, each node's bound to ground; ground last
    node_hi[-1] = 0.0
    to_ground = mon_b == GROUND
    node_hi[mon_a[to_ground]] = (hi + tol) * mon_base[to_ground]
    triangle = node_hi[a] + node_hi[b]  # |v_a − v_b| ≤ |v_a| + |v_b|
    sigma = np.fmin(np.where(np.isfinite(at_pair), (hi + tol) * at_pair, np.inf), triangle)
    lm, owner = net.load_models, lb.owner
    model = lm.model[owner]
    n_load = lb.n
    switching = model != CONSTANT_Z
    rho[:n_load] = np.where(switching, np.maximum(rho[:n_load], (lm.vminpu[owner] - tol) * lb.vbase_v), rho[:n_load])
    capped = (model == CONSTANT_I) | (model == EXPONENTIAL)
    sigma[:n_load] = np.where(capped, np.minimum(sigma[:n_load], (lm.vmaxpu[owner] + tol) * lb.vbase_v), sigma[:n_load])
    rho[n_load:] = np.maximum(rho[n_load:], (DER_VMIN_PU - tol) * db.vbase_v)
    return reach, rho, sigma, nodes


def _law_extremes(exponent: np.ndarray, cap: np.ndarray, u_lo: np.ndarray, u_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per branch the largest s(u) and |s′(u)| over [u_lo, u_hi] of the law s = u^e up to
    `cap`, u²·cap^(e−2) above it (module docstring: each piece's extremes at its ends); inf
    where the range is unbounded and the law grows."""
    s_max = np.zeros(exponent.shape)
    d_max = np.zeros(exponent.shape)
    with np.errstate(all="ignore"):
        lower_end = np.minimum(u_hi, cap)  # the power law's piece: [u_lo, min(u_hi, cap)]
        for u in (u_lo, lower_end):
            on = u_lo <= lower_end
            s_max = np.where(on, np.fmax(s_max, u**exponent), s_max)
            d_max = np.where(on, np.fmax(d_max, np.abs(exponent * u ** (exponent - 1.0))), d_max)
        upper_start = np.maximum(u_lo, cap)  # the impedance piece: [max(u_lo, cap), u_hi]
        for u in (upper_start, u_hi):
            on = (upper_start <= u_hi) & np.isfinite(cap)
            s_max = np.where(on, np.fmax(s_max, u**2 * cap ** (exponent - 2.0)), s_max)
            d_max = np.where(on, np.fmax(d_max, 2.0 * u * cap ** (exponent - 2.0)), d_max)
    return np.nan_to_num(s_max, nan=np.inf), np.nan_to_num(d_max, nan=np.inf)


def contraction(
    net: PhaseNetwork, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, der_q_mvar: np.ndarray, tol: float
) -> np.ndarray:
    """(S,) the contraction factor L of S snapshots (arrays (S, n) as the power flow takes
    them) on `net` at its elements' taps, the region's rows widened by `tol` p.u. (module
    docstring); inf where some branch's current has no Lipschitz bound there."""
    reach, rho, sigma, _ = _reach(net, float(tol))
    lb, db = net.load_branches, net.der_branches
    n_load = lb.n
    p = np.atleast_2d(load_p_mw)[:, lb.owner] * lb.share * 1e6  # W at the law's reference
    q = np.atleast_2d(load_q_mvar)[:, lb.owner] * lb.share * 1e6
    exp_p, exp_q, cap = load_law(net)
    vb = lb.vbase_v
    u_lo, u_hi = rho[:n_load] / vb, sigma[:n_load] / vb
    sp_max, dp_max = _law_extremes(exp_p, cap, u_lo, u_hi)
    sq_max, dq_max = _law_extremes(exp_q, cap, u_lo, u_hi)
    with np.errstate(all="ignore"):  # inf where a range is unbounded: no certificate
        general = (np.abs(p) * sp_max + np.abs(q) * sq_max) / rho[:n_load] ** 2
        general += (np.abs(p) * dp_max + np.abs(q) * dq_max) / (vb * rho[:n_load])
        impedance = (net.load_models.model[lb.owner] == CONSTANT_Z)[None, :]
        k_load = np.where(impedance, np.hypot(p, q) / vb**2, general)
        k_load = np.where((p == 0) & (q == 0), 0.0, k_load)
        s_der = np.hypot(np.atleast_2d(der_p_mw)[:, db.owner], np.atleast_2d(der_q_mvar)[:, db.owner]) * db.share * 1e6
        k_der = np.where(s_der == 0, 0.0, s_der / rho[n_load:] ** 2)
    k = np.nan_to_num(np.concatenate([k_load, k_der], axis=1), nan=np.inf, posinf=np.inf)
    if not np.isfinite(reach).all():
        return np.full(len(k), np.inf)
    with np.errstate(invalid="ignore"):
        out = np.max(k @ reach.T, axis=1, initial=0.0) if reach.size else np.zeros(len(k))
    return np.where(np.isfinite(k).all(axis=1), out, np.inf)


def within_region(net: PhaseNetwork, flow: PhaseFlowResult, tol: float) -> np.ndarray:
    """(S,) the flow converged and every branch's |d| lies in its [ρ, σ] (`_reach`) and
    every monitored voltage in the band, each widened by `tol` p.u."""
    _, rho, sigma, _ = _reach(net, float(tol))
    lb, db = net.load_branches, net.der_branches
    a = np.concatenate([lb.a, db.a])
    b = np.concatenate([lb.b, db.b])
    v = np.concatenate([flow.v, np.zeros((flow.n_snapshots, 1))], axis=1)  # ground last
    d = np.abs(v[:, a] - v[:, np.where(b == GROUND, -1, b)])
    lo, hi = net.band
    with np.errstate(invalid="ignore"):
        band = (flow.vm.min(axis=1, initial=np.inf) >= lo - tol) & (flow.vm.max(axis=1, initial=-np.inf) <= hi + tol)
        rows = ((d >= rho) & (d <= sigma)).all(axis=1)
    return np.asarray(flow.converged, dtype=bool) & band & rows


def unique_point(
    net: PhaseNetwork,
    flow: PhaseFlowResult,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    der_q_mvar: np.ndarray,
    tol: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(unique, L) per snapshot of `flow` (the power flow on `net`, at its taps, at these
    powers): unique where L < CONTRACTION_MAX and the flow's point lies in the region
    (`within_region`) — the point is then the only one that meets the OPF's constraints."""
    factor = contraction(net, load_p_mw, load_q_mvar, der_p_mw, der_q_mvar, tol)
    return within_region(net, flow, tol) & (factor < CONTRACTION_MAX), factor
