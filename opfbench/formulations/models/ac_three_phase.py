"""The exact three-phase AC OPF on a `PhaseNetwork` (CasADi NLP, solved by IPOPT), in
rectangular node voltages.

Rectangular, not polar: the node-level model is a current-injection one (`Y·V =
I_source + I_branches(V)`, `opfbench.powerflow.multiphase`), linear in the real and
imaginary parts of V except for the load and DER branches; delta branches and
phase-to-phase band limits are differences of node voltages, which are linear in
rectangular coordinates and not in polar ones; and neutral nodes near 0 V have no useful
angle.

Per unit: node voltages v = V / (the node's base, `PhaseNetwork.node_base_v`), powers on
1 MVA (MW and MVAr), currents in p.u. of 1 MVA / the node's base. The problem:

    minimize   losses (kW) = P_source − Σ P_loads(v) + Σ P_DER
    over       v (every node, real and imaginary part), q (each DER's Q, MVAr)
    subject to Y·v = i_source + Σ branch currents(v, q)        (every node, p.u.)
               band_low ≤ |v_a − v_b| / base ≤ band_high        (`PhaseNetwork.monitored`)
               vminpu ≤ u_load                                   (loads that switch law)
               u_load ≤ vmaxpu                                   (constant |I| and exponential)
               −q_limit ≤ q ≤ q_limit                            (the (1 − k) capability)

- The source is its EMF behind its Thevenin admittance (the power flow's model): the EMF's
  three phase voltages are fixed, the source bus's are variables. P_source is the power
  it delivers into its bus (the Thevenin impedance's own losses excluded, as OpenDSS's and
  the power flow's losses).
- Loads as the power flow models them (`multiphase.branches.BranchLaw`): the law of each
  OpenDSS model in band, and above vmaxpu the impedance switch of models 1 (constant PQ)
  and 5 (constant |I|) written exactly with min(u, vmaxpu). The ramp below vminpu is not
  modelled: a switching load stays at or above its vminpu (a constraint, the OpenDSS
  default 0.95 p.u.); a constant-|I| or exponential load (models 5, 4) also at or below
  its vmaxpu (model 4's law jumps there; for model 5 it keeps the SDP relaxation's hull
  of u = √w concave — `sdp_three_phase`).
- DER: constant-power branches, P fixed (parameter), one Q per DER split equally over
  its phases (the power flow's and the rule engine's convention, OpenDSS's kvar), each
  branch's voltage at or above `DER_VMIN_PU`.
- Regulator and transformer taps fixed where the case settled them (they are in Y).
- Built with `curtail` (`acopf:curtail=true`, the frontier of the optimum that may
  curtail): each DER's P is a decision too, in [min(P, 0), P] of the power it has, its Q
  within the capability at the P it delivers (`problem.PqCapability`: the power-factor
  pieces and the S̄ circle, scaled by 1 − k), and the objective adds the power curtailed.

Built once per network: the load and DER powers and the Q limits are NLP parameters
and variable bounds; IPOPT solves cold from the power flow's no-action point or warm from
the previous answer (`solvers.ipopt_adapter`).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from opfbench.formulations.model import formulation
from opfbench.formulations.problem import PqCapability
from opfbench.formulations.solvers.ipopt_adapter import IpoptNlp, IpoptSolve
from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_PQ, CONSTANT_Z, EXPONENTIAL, Branches
from opfbench.registry.specs import UNBALANCED

KW_PER_MW = 1e3
DER_VMIN_PU = 0.9
"""A DER branch's voltage stays at or above this (p.u. of its base): OpenDSS's PVSystem
default vminpu, below which its law is no longer constant power. Never binding at a
normal operating point; it bounds a delta unit's current, which the SDP relaxation
(`sdp_three_phase`) needs to cap that current's lifted square."""
OPTIONS = {
    "ipopt.nlp_scaling_max_gradient": 1e4,
    "ipopt.obj_scaling_factor": 1.0,
    "ipopt.tol": 1e-10,
    "ipopt.acceptable_tol": 1e-6,
    "ipopt.acceptable_iter": 2,
    "ipopt.acceptable_obj_change_tol": 1e-8,
}
"""IPOPT's options for this NLP.
- Rows are scaled only above a gradient of 1e4: IPOPT's gradient-based scaling at its
  default limit (100) reads the near-zero-impedance switches' rows (admittances of 1e6
  p.u. and more) and shrinks every other row, and IPOPT then ends in restoration.
- tol 1e-10, or acceptable once the objective (kW) moves less than 1e-8 (relative) over 2
  iterations at the acceptable level (1e-6). Why not IPOPT's usual tol 1e-8: the same
  scaling reads the stiff source's Thevenin admittance in the objective's gradient (kW
  per p.u. of the source bus's voltage: ~6e7 on ieee123) and scales the objective by
  ~2e-4, so a tol on the scaled problem is ~5000 times looser on the losses. At 1e-8 IPOPT
  stopped with the barrier's share still in them: on ieee123 1e-5–4e-5 of the losses
  above the local optimum and above the power flow at the SDP relaxation's Q — no
  certificate at 1e-6 can be measured against such a point. The objective-change rule
  stops the iterations that 1e-10 alone would add (round-off in the switches' and
  near-ideal regulators' rows keeps the scaled error above it); at 1e-9 instead of 1e-8
  ieee13's restarts ran out of iterations. It also replaces the earlier re-solve to 1e-10
  where a 1e-8 point was not confirmed (ieee13's regulators: node voltages 4e-6 p.u. off
  the equations, the objective 6e-4 off the power flow's losses). A raised
  `obj_scaling_factor` (×100, ×1000) reaches the same point but made the
  cold solves slower (×1000: 5× the iterations, and one ended in restoration)."""


def sparse_dm(m: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi DM."""
    coo = sp.coo_matrix(m)
    return ca.DM.triplet(coo.row.tolist(), coo.col.tolist(), ca.DM(coo.data), coo.shape[0], coo.shape[1])


@dataclass(frozen=True, eq=False)
class BranchEnds:
    """Load or DER branches in p.u.: node `a`, node `b` (n_node for GROUND: a zero row),
    `ratio_b` = base_b / base_a, `c` = base_a / the branch's base (u = c·|w|, w the branch
    voltage in p.u. of node a's base), and `inject` (n_node, n_branch): the p.u. current
    of each branch (a → b, in a's base) as nodal injections (+1 at a, −ratio_b at b)."""

    a: np.ndarray
    b: np.ndarray
    ratio_b: np.ndarray
    c: np.ndarray
    inject: sp.csr_matrix

    @classmethod
    def of(cls, net: PhaseNetwork, br: Branches) -> BranchEnds:
        base = np.append(net.node_base_v, 1.0)
        a, b = br.a, np.where(br.b == GROUND, net.n_node, br.b)
        ratio_b = np.where(br.b == GROUND, 0.0, base[b] / base[a])
        cols = np.arange(br.n)
        to = br.b != GROUND
        inject = sp.csr_matrix(
            (np.concatenate([np.ones(br.n), -ratio_b[to]]), (np.concatenate([a, b[to]]), np.concatenate([cols, cols[to]]))),
            shape=(net.n_node, br.n),
        )
        return cls(a, b, ratio_b, base[a] / br.vbase_v, inject)

    def voltage(self, e: ca.SX, f: ca.SX) -> tuple[ca.SX, ca.SX]:
        """The branch voltages' real and imaginary parts (p.u. of node a's base)."""
        ez, fz = ca.vertcat(e, 0), ca.vertcat(f, 0)
        ratio = ca.DM(self.ratio_b)
        return ez[self.a.tolist()] - ratio * ez[self.b.tolist()], fz[self.a.tolist()] - ratio * fz[self.b.tolist()]


def load_law(net: PhaseNetwork) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per load branch: the exponents of u in the P and Q parts of its power (in band) and
    the voltage `cap` above which its law is the power flow's impedance (models 1 and 5:
    vmaxpu; others: inf). The current factor is then h(u) = u·min(u, cap)^(exponent − 2):
    u^(exponent − 1) in band, u/vmaxpu² (model 1) or u/vmaxpu (model 5) above cap."""
    lm, owner = net.load_models, net.load_branches.owner
    model = lm.model[owner]
    exp_p = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], lm.cvr_p[owner])
    exp_q = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], lm.cvr_q[owner])
    capped = (model == CONSTANT_PQ) | (model == CONSTANT_I)
    return exp_p, exp_q, np.where(capped, lm.vmaxpu[owner], np.inf)


@formulation(
    "ac3",
    role="exact",
    networks=UNBALANCED,
    serves_problem=True,
    summary="three-phase AC OPF (node-level, rectangular voltages, IPOPT): the optimum on unbalanced feeders",
)
class ThreePhaseAc:
    """The three-phase AC OPF of `net` (module docstring). `solve(load_p_mw, load_q_mvar,
    der_p_mw, q_limit_mvar, x0=…, start=…)` one snapshot; `initial(v)` the NLP point at
    node voltages v (complex V) with Q = 0 (a cold start from a power flow)."""

    def __init__(self, net: PhaseNetwork, slack_export: bool = True, curtail: bool = False):
        self.net, self.curtail = net, curtail
        n, n_load, n_der = net.n_node, net.n_load, len(net.ders)
        base = net.node_base_v
        y = sp.diags(base) @ net.ybus @ sp.diags(base) / 1e6  # p.u. on 1 MVA and each node's base
        src = net.source
        i_src = np.zeros(n, dtype=complex)
        i_src[src.nodes] = (src.y_s @ src.emf_v) * base[src.nodes] / 1e6
        y_s = np.diag(base[src.nodes]) @ src.y_s @ np.diag(base[src.nodes]) / 1e6
        e_src = src.emf_v / base[src.nodes]

        q = ca.SX.sym("q", n_der)
        e, f = ca.SX.sym("e", n), ca.SX.sym("f", n)
        p_load, q_load = ca.SX.sym("p_load", n_load), ca.SX.sym("q_load", n_load)
        p_der = ca.SX.sym("p_der", n_der)
        g_re, g_im = sparse_dm(y.real), sparse_dm(y.imag)
        res_re = ca.mtimes(g_re, e) - ca.mtimes(g_im, f) - ca.DM(i_src.real)
        res_im = ca.mtimes(g_re, f) + ca.mtimes(g_im, e) - ca.DM(i_src.imag)
        rows = []

        lb = net.load_branches
        loads = BranchEnds.of(net, lb)
        exp_p, exp_q, cap = load_law(net)
        wr, wi = loads.voltage(e, f)
        mag = ca.sqrt(wr**2 + wi**2)
        u = ca.DM(loads.c) * mag
        m = ca.fmin(u, ca.DM(cap))  # `load_law`
        h_p = u * m ** ca.DM(exp_p - 2.0)
        h_q = u * m ** ca.DM(exp_q - 2.0)
        share = ca.DM(lb.share)
        pb, qb = share * p_load[lb.owner.tolist()], share * q_load[lb.owner.tolist()]
        # current drawn a → b, p.u. of a's base: (P·h_P − jQ·h_Q)·(w/|w|)·c
        cr, ci = pb * h_p * ca.DM(loads.c) / mag, -qb * h_q * ca.DM(loads.c) / mag
        i_re, i_im = cr * wr - ci * wi, cr * wi + ci * wr
        inject = sparse_dm(loads.inject)
        res_re += ca.mtimes(inject, i_re)
        res_im += ca.mtimes(inject, i_im)
        load_p_drawn = ca.sum1(u * pb * h_p)

        db = net.der_branches
        ders = BranchEnds.of(net, db)
        dr, di = ders.voltage(e, f)
        ps, qs = ca.DM(db.share) * p_der[db.owner.tolist()], ca.DM(db.share) * q[db.owner.tolist()]
        d2 = dr**2 + di**2
        # injected current conj(S / w): (P·wr + Q·wi + j(P·wi − Q·wr)) / |w|²
        inj = sparse_dm(ders.inject)
        res_re -= ca.mtimes(inj, (ps * dr + qs * di) / d2)
        res_im -= ca.mtimes(inj, (ps * di - qs * dr) / d2)

        # source power into its bus: v·conj(y_s·(e_src − v))
        vs_re, vs_im = e[src.nodes.tolist()], f[src.nodes.tolist()]
        di_re = ca.DM(e_src.real) - vs_re
        di_im = ca.DM(e_src.imag) - vs_im
        is_re = ca.mtimes(ca.DM(y_s.real), di_re) - ca.mtimes(ca.DM(y_s.imag), di_im)
        is_im = ca.mtimes(ca.DM(y_s.real), di_im) + ca.mtimes(ca.DM(y_s.imag), di_re)
        p_source = ca.sum1(vs_re * is_re + vs_im * is_im)
        losses = KW_PER_MW * (p_source - load_p_drawn + ca.sum1(p_der))

        a, b, base_m, _ = net.monitored
        ez, fz = ca.vertcat(e, 0), ca.vertcat(f, 0)
        scale = ca.DM(np.append(base, 1.0)[a] / base_m)
        mr = scale * (ez[a.tolist()] - ca.DM(np.where(b == GROUND, 0.0, 1.0)) * ez[np.where(b == GROUND, n, b).tolist()])
        mi = scale * (fz[a.tolist()] - ca.DM(np.where(b == GROUND, 0.0, 1.0)) * fz[np.where(b == GROUND, n, b).tolist()])
        band_sq = mr**2 + mi**2
        switching = np.flatnonzero(net.load_models.model[lb.owner] != CONSTANT_Z)
        bounded = np.flatnonzero(np.isin(net.load_models.model[lb.owner], (CONSTANT_I, EXPONENTIAL)))
        lo, hi = net.band
        rows = [
            (res_re, np.zeros(n), np.zeros(n)),
            (res_im, np.zeros(n), np.zeros(n)),
            (band_sq, np.full(len(a), lo**2), np.full(len(a), hi**2)),
            (u[switching.tolist()], net.load_models.vminpu[lb.owner][switching], np.full(switching.size, np.inf)),
            (u[bounded.tolist()], np.full(bounded.size, -np.inf), net.load_models.vmaxpu[lb.owner][bounded]),
            (ca.DM(ders.c**2) * d2, np.full(db.n, DER_VMIN_PU**2), np.full(db.n, np.inf)),
        ]
        if not slack_export:  # the source may not take power back from the feeder
            rows.append((p_source, np.zeros(1), np.full(1, np.inf)))
        self.n_monitored = len(a)
        self.band_rows = slice(2 * n, 2 * n + len(a))  # where `solve` puts another band
        if curtail:  # P a decision in [min(P, 0), P]; the cost adds the power curtailed; Q within the capability at P
            p_avail = ca.SX.sym("p_avail", n_der)
            slope, offset, reserve = ca.SX.sym("slope", 2 * n_der), ca.SX.sym("offset", 2 * n_der), ca.SX.sym("share", 1)
            pq = PqCapability.of(net, 0.0, base_mva=1.0)  # which units have the S̄ circle; slopes and share: parameters
            rows += [(r.expr, r.lo, r.hi) for r in pq.rows(q, p_der, slope, offset, reserve)]
            x, params = ca.vertcat(q, p_der, e, f), ca.vertcat(p_load, q_load, p_avail, slope, offset, reserve)
            cost = losses + KW_PER_MW * ca.sum1(p_avail - p_der)
        else:
            x, params, cost = ca.vertcat(q, e, f), ca.vertcat(p_load, q_load, p_der), losses
        nlp = {"x": x, "p": params, "f": cost, "g": ca.vertcat(*(r[0] for r in rows))}
        self.nlp = IpoptNlp(
            f"ac3_{net.name}{'_curtail' if curtail else ''}",
            nlp,
            np.concatenate([r[1] for r in rows]),
            np.concatenate([r[2] for r in rows]),
            slice(0, (2 if curtail else 1) * n_der),
            OPTIONS,
        )
        self.n_der = n_der

    def initial(self, v: np.ndarray, der_p_mw: np.ndarray | None = None, q_mvar: np.ndarray | None = None) -> np.ndarray:
        """The NLP point at node voltages `v` (n_node,) complex V, Q = `q_mvar` (default 0;
        and, built with `curtail`, P = `der_p_mw`)."""
        pu = np.asarray(v) / self.net.node_base_v
        p = [np.asarray(der_p_mw, dtype=float)] if self.curtail and der_p_mw is not None else []
        q = np.zeros(self.n_der) if q_mvar is None else np.asarray(q_mvar, dtype=float)
        return np.concatenate([q, *p, pu.real, pu.imag])

    def voltages(self, solve: IpoptSolve) -> np.ndarray:
        """(n_node,) complex V of a solve's point."""
        n = self.net.n_node
        x = solve.x[(2 if self.curtail else 1) * self.n_der :]
        return (x[:n] + 1j * x[n:]) * self.net.node_base_v

    def solve(
        self,
        load_p_mw: np.ndarray,
        load_q_mvar: np.ndarray,
        der_p_mw: np.ndarray,
        q_limit_mvar: np.ndarray,
        x0: np.ndarray | None = None,
        start: IpoptSolve | None = None,
        band: tuple[float, float] | None = None,
        capability: tuple[PqCapability, np.ndarray] | None = None,
    ) -> IpoptSolve:
        """One snapshot: loads' P and Q (n_load,) at their law's reference, DER P (n_der,),
        usable |Q| (n_der,) MVAr; warm from `start`, else cold from `x0` (`initial`);
        `band` (low, high) p.u. in place of the feeder's (a widened band: the frontier).
        Built with `curtail`: `capability` — the `PqCapability` at the reserve (MW) and its
        pieces' offsets (n_der, 2) MW (`problem.capability_offsets`) — bounds Q in place
        of `q_limit_mvar`, P lies in [min(P, 0), P] of `der_p_mw`; the solve's `q_pu`
        holds Q, then P."""
        big = np.full(2 * self.net.n_node, np.inf)
        if self.curtail:
            if capability is None:
                raise ValueError("a solve that may curtail needs the capability (PqCapability, offsets)")
            cap, offset = capability
            pieces = [cap.slope.T.reshape(-1), offset.T.reshape(-1), [cap.share]]
            p = np.concatenate([load_p_mw, load_q_mvar, der_p_mw, *pieces])
            free = np.full(self.n_der, np.inf)
            lbx = np.concatenate([-free, np.minimum(der_p_mw, 0.0), -big])
            ubx = np.concatenate([free, der_p_mw, big])
        else:
            p = np.concatenate([load_p_mw, load_q_mvar, der_p_mw])
            lbx = np.concatenate([-q_limit_mvar, -big])
            ubx = np.concatenate([q_limit_mvar, big])
        if x0 is None and start is None:
            raise ValueError("a cold solve needs a start point x0 (ThreePhaseAc.initial)")
        lbg, ubg = self.nlp.lbg, self.nlp.ubg
        if band is not None and tuple(band) != tuple(self.net.band):
            lbg, ubg = lbg.copy(), ubg.copy()
            lbg[self.band_rows], ubg[self.band_rows] = band[0] ** 2, band[1] ** 2
        return self.nlp.solve(p, lbx, ubx, x0 if x0 is not None else start.x, start, lbg, ubg)  # type: ignore[union-attr]
