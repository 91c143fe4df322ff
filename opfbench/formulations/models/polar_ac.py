"""The exact AC OPF in polar form (CasADi NLP, solved by IPOPT).

The problem is `problem.OpfProblem` (per unit on `net.base_mva`): minimize branch losses
= P_slack + Σ P_fixed − Σ Gsh·|V|² (kW) over the DER Q, |V| and θ of every non-slack bus,
subject to the AC power balance (π model, `problem.PiBranches`) and the slack rule of
`OpfProblem.balance`, |V_slack| = v_slack, θ_slack = 0, vmin ≤ |V| ≤ vmax elsewhere and
−(1 − k)·Qmax(P) ≤ Q ≤ (1 − k)·Qmax(P) with DER P fixed.

`AcOpf` builds the NLP once per (network, slack_export) — fixed injections are NLP
parameters, Q and |V| limits variable bounds — sparse throughout (vector expressions,
sparse incidence; CasADi SX below MX_MIN_BUSES buses, MX from there on); IPOPT solves it
cold or warm (`solvers.ipopt_adapter`). With `curtail` the DER's active power is a
variable too, within [min(P, 0), P] of the power P it has, Q within the capability at the
power delivered (`problem.PqCapability`: linear pieces and the S̄ circle, their slopes,
offsets and the share 1 − k parameters), and the objective the losses plus the power
curtailed (`solve_curtailing`).
"""

from __future__ import annotations

from typing import TypeVar

import casadi as ca
import numpy as np
import scipy.sparse as sp

from opfbench.formulations.model import formulation
from opfbench.formulations.problem import CurtailData, OpfProblem, PqCapability, incidence
from opfbench.formulations.solvers.ipopt_adapter import IpoptNlp, IpoptSolve
from opfbench.network import Network

# From this many buses the NLP is written in CasADi MX (vector operations) instead of SX
# (scalar graph): creating an IPOPT instance derives the Jacobian and Hessian on the graph,
# an order of magnitude faster in MX on feeder1k and feeder10k, while on small cases SX
# solves faster (`python -m opfbench.bench opf` times the paper33 solves).
MX_MIN_BUSES = 500
Sym = TypeVar("Sym", ca.SX, ca.MX)  # the CasADi symbol type of one NLP


def _sparse_dm(m: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi DM (no dense n×n intermediate)."""
    coo = sp.coo_matrix(m)
    return ca.DM.triplet(coo.row.tolist(), coo.col.tolist(), ca.DM(coo.data), coo.shape[0], coo.shape[1])


def _nlp(problem: OpfProblem, sym: type[Sym], curtail: bool = False) -> tuple[dict[str, Sym], list]:
    """The NLP {x, p, f, g} of `problem` in CasADi symbols `sym` (SX or MX), and its
    constraint rows (`OpfProblem.balance`, then with `curtail` the capability's)."""
    net = problem.net
    n, n_der, m = net.n_bus, len(net.ders), problem.others.size
    theta_o, vm_o, q = sym.sym("theta", m), sym.sym("vm", m), sym.sym("q", n_der)
    p_fixed, q_fixed = sym.sym("p_fixed", n), sym.sym("q_fixed", n)
    if curtail:  # the DER's P a variable: the fixed injections exclude it
        p_der, p_avail = sym.sym("p_der", n_der), sym.sym("p_avail", n_der)
        slope, offset, share = sym.sym("slope", 2 * n_der), sym.sym("offset", 2 * n_der), sym.sym("share", 1)
    place = _sparse_dm(incidence(problem.others, n))  # non-slack values onto all buses
    at_slack = np.zeros(n)
    at_slack[problem.slack] = problem.v_slack
    theta = ca.mtimes(place, theta_o)
    vm = ca.mtimes(place, vm_o) + ca.DM(at_slack)

    br = problem.branches
    f, t = br.f.tolist(), br.t.tolist()
    vm_f, vm_t = vm[f], vm[t]
    vv, angle = vm_f * vm_t, theta[f] - theta[t]
    c, s = vv * ca.cos(angle), vv * ca.sin(angle)
    v2 = vm**2
    p_f, q_f, p_t, q_t = br.flows(vm_f**2, vm_t**2, c, s, lambda a, e: ca.DM(a) * e)
    at_from, at_to = _sparse_dm(br.at_from), _sparse_dm(br.at_to)
    p_in = p_fixed + ca.mtimes(_sparse_dm(problem.der_at_bus), p_der) if curtail else p_fixed
    mismatch_p = ca.mtimes(at_from, p_f) + ca.mtimes(at_to, p_t) + ca.DM(problem.gsh) * v2 - p_in
    mismatch_q = (
        ca.mtimes(at_from, q_f)
        + ca.mtimes(at_to, q_t)
        - ca.DM(problem.bsh) * v2
        - q_fixed
        - ca.mtimes(_sparse_dm(problem.der_at_bus), q)
    )
    rows = problem.balance(mismatch_p, mismatch_q, lambda e, i: e[i.tolist()])
    losses = mismatch_p[problem.slack] + ca.sum1(p_in) - ca.dot(ca.DM(problem.gsh), v2)
    if not curtail:
        x, params, cost = ca.vertcat(theta_o, vm_o, q), ca.vertcat(p_fixed, q_fixed), losses
    else:
        x, cost = ca.vertcat(theta_o, vm_o, q, p_der), losses + ca.sum1(p_avail - p_der)
        params = ca.vertcat(p_fixed, q_fixed, p_avail, slope, offset, share)
        rows += PqCapability.of(net, 0.0).rows(q, p_der, slope, offset, share)  # slopes and share: parameters
    nlp = {"x": x, "p": params, "f": problem.kw_per_pu * cost, "g": ca.vertcat(*(r.expr for r in rows))}
    return nlp, rows


@formulation(
    "polar-ac",
    role="exact",
    serves_problem=True,
    summary="the exact AC OPF in polar form (CasADi NLP, IPOPT)",
)
class AcOpf:
    """The polar AC OPF of one network, built once; `solve` per snapshot.

    Decision vector x = [θ (non-slack buses, rad), |V| (non-slack, p.u.), Q_DER (p.u.)].
    NLP parameters: fixed injections [P_fixed; Q_fixed] (2·n_bus, p.u.).
    Constraints g: the rows of `OpfProblem.balance` (P and Q mismatch at the non-slack
    buses = 0, then, with `slack_export=False`, the slack's P ≥ 0).
    """

    def __init__(self, net: Network, slack_export: bool = True, curtail: bool = False):
        self.problem = problem = OpfProblem.of(net, slack_export)
        self.net, self.slack_export, self.curtail = net, slack_export, curtail
        self.others = problem.others
        m, n_der = self.others.size, len(net.ders)
        nlp, rows = _nlp(problem, ca.MX, curtail) if net.n_bus >= MX_MIN_BUSES else _nlp(problem, ca.SX, curtail)
        lbg, ubg = np.concatenate([r.lo for r in rows]), np.concatenate([r.hi for r in rows])
        self.ipopt = IpoptNlp("acopf_curtail" if curtail else "acopf", nlp, lbg, ubg, setpoints=slice(2 * m, None))
        inf = np.full(m, np.inf)
        self._lbx_fixed = np.concatenate([-inf, problem.vm_min])
        self._ubx_fixed = np.concatenate([inf, problem.vm_max])
        self.flat_start = np.concatenate([np.zeros(m), np.ones(m), np.zeros((2 if curtail else 1) * n_der)])

    def solve(self, s_fixed: np.ndarray, q_limit: np.ndarray, start: IpoptSolve | None = None) -> IpoptSolve:
        """Solve one snapshot: fixed injections `s_fixed` (n_bus,) complex p.u., usable Q
        limits `q_limit` (n_der,) p.u. With `start` (a previous solve) IPOPT is warm-started
        from its primal and dual point; without, it starts cold from the flat start."""
        return self.ipopt.solve(
            np.concatenate([s_fixed.real, s_fixed.imag]),
            np.concatenate([self._lbx_fixed, -q_limit]),
            np.concatenate([self._ubx_fixed, q_limit]),
            self.flat_start,
            start,
        )

    def solve_curtailing(
        self, data: CurtailData, i: int, capability: PqCapability, start: IpoptSolve | None = None
    ) -> IpoptSolve:
        """Solve snapshot i of `data` where the DER's active power is a variable too (built
        with `curtail`): its `q_pu` holds Q, then P (p.u.)."""
        inf = np.full(len(self.net.ders), np.inf)
        params = [data.s_fixed[i].real, data.s_fixed[i].imag, data.p_avail[i], capability.slope.T.reshape(-1)]
        params += [data.offset[i].T.reshape(-1), [capability.share]]
        return self.ipopt.solve(
            np.concatenate(params),
            np.concatenate([self._lbx_fixed, -inf, data.p_low[i]]),
            np.concatenate([self._ubx_fixed, inf, data.p_avail[i]]),
            np.concatenate([self.flat_start[: -2 * len(inf)], np.zeros(len(inf)), data.p_avail[i]]),
            start,
        )
