"""Centralized AC OPF (polar form, CasADi + IPOPT) with a certified fast path and a
recorded failure policy.

The problem is `problem.OpfProblem` (per unit on `net.base_mva`): minimize branch losses
= P_slack + Σ P_fixed − Σ Gsh·|V|² (kW) over the DER Q, |V| and θ of every non-slack bus,
subject to the AC power balance (π model, `problem.PiBranches`) and the slack rule of
`OpfProblem.balance`, |V_slack| = v_slack, θ_slack = 0, vmin ≤ |V| ≤ vmax elsewhere and
−(1 − k)·Qmax(P) ≤ Q ≤ (1 − k)·Qmax(P) with DER P fixed.

`AcOpf` builds the NLP once per (network, slack_export) — fixed injections are NLP
parameters, Q and |V| limits variable bounds — sparse throughout (vector expressions,
sparse incidence; CasADi SX below MX_MIN_BUSES buses, MX from there on), with two IPOPT
instances, each created on first use: a cold one (flat
start, IPOPT's defaults) and a warm one (primal and dual start from a previous solution, `warm_start_init_point`,
small initial barrier). `bound_relax_factor = 0`: IPOPT's iterates stay within the Q
and |V| bounds, so the reported objective cannot dip below the SOCP bound by a bound
overshoot. Every solve returns its status, iterations and time from IPOPT's statistics.

`run_acopf` settles every snapshot of a scenario. With `solver="auto"` (default) it
first takes the certified fast path: the SOCP relaxation (`socp.socp_solves`, shared
with the `socp` strategy on the same scenario and k) is solved on every snapshot and
its setpoints are evaluated by ONE batched AC power flow. Where the relaxation is
infeasible the AC OPF is too (status "infeasible", no action, IPOPT not run); where its
setpoints are AC-feasible (`OpfProblem.feasible`) and their AC losses lie within CERTIFY_RTOL (relative) of the
relaxation's bound — a lower bound on every AC-feasible point's losses — they are the
AC optimum up to that tolerance: recorded with status "ok", extra["certified_by"] =
"socp", and IPOPT is skipped. IPOPT (warm-started from its last successful solution)
solves only the other snapshots. `solver="ipopt"` solves every snapshot with IPOPT
(the paper's question is how often a nonlinear OPF solver fails: `opfbench run
--acopf-solver ipopt` answers it for `acopf` and `acopf-paper`).

IPOPT's snapshots follow a failure policy, recorded per snapshot:

- `chain` (default): warm IPOPT → cold IPOPT → the SOCP relaxation's setpoints if, AC
  evaluated, they are feasible → no action if feasible. Status "ok" / "fallback-cold" /
  "fallback-socp" / "fallback-no-action".
- `paper`: IPOPT once (warm when possible); on failure, no action — as the paper did.

When no point is found feasible, the setpoints are those of no action (extra["fallback"]
= "no-action", its AC losses reported) and the status is "infeasible" if IPOPT reported
infeasibility or the SOCP relaxation is infeasible (which proves it), "solver-failed"
otherwise. With `lower_bound=True` (default) the relaxation's optimum is the result's
`lower_bound_kw`, which certifies the optimality gap of every strategy on the snapshot
(the fast path solves the relaxation anyway, so its bound is reported then too).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np
import scipy.sparse as sp

from opfbench.formulations.cache import per_thread
from opfbench.formulations.problem import (
    FALLBACK_COLD,
    FALLBACK_NO_ACTION,
    FALLBACK_SOCP,
    FROM_COLD,
    FROM_NO_ACTION,
    FROM_SOCP,
    FROM_SOLVER,
    SOLVER_FAILED,
    OpfProblem,
    SnapshotData,
    check_option,
    diagnostics,
    evaluated_result,
    incidence,
    snapshot_data,
)
from opfbench.formulations.socp import SocpSolve, relaxation, socp_diagnostics, socp_solves
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult, solve_pf, solve_pf_batch
from opfbench.result import INFEASIBLE, OK, StrategyResult
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now

Fallback = Literal["chain", "paper"]
FALLBACKS = ("chain", "paper")
Solver = Literal["auto", "ipopt"]
SOLVERS = ("auto", "ipopt")
CERTIFY_RTOL = 1e-6  # fast path: AC losses of the SOCP point ≤ bound·(1 + this) (relative)

TOLERANCE = 1e-10  # IPOPT tol (scaled NLP error; objective in kW)
# IPOPT's gradient-based scaling shrinks the kW objective; without this extra factor the
# barrier left active Q bounds ~3e-6 MVAr short, ~1e-5 relative above the optimum on
# case69-der (seen against the exact SOCP bound). With it: ≤ 1e-6, and fewer iterations.
OBJECTIVE_SCALING = 100.0
MAX_ITER = 300
# From this many buses the NLP is written in CasADi MX (vector operations) instead of SX
# (scalar graph). Creating an IPOPT instance derives the Jacobian and Hessian on the
# graph: feeder10k 6.8 s in SX, 0.4 s in MX (cold solve 0.9 vs 1.1 s); feeder1k 0.54 vs
# 0.05 s (solve equal). On small cases SX solves faster (paper33, warm: 2.4 vs 3.8 ms).
MX_MIN_BUSES = 500
IPOPT_OPTIONS = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "record_time": True,
    "ipopt.tol": TOLERANCE,
    "ipopt.obj_scaling_factor": OBJECTIVE_SCALING,
    "ipopt.max_iter": MAX_ITER,
    "ipopt.bound_relax_factor": 0.0,  # iterates never leave the Q and |V| bounds
    # The KKT systems are small and sparse: skip MUMPS' scaling, AMD ordering (≈10 % faster).
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
    "ipopt.mumps_pivot_order": 0,
}
WARM_OPTIONS = {
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-8,  # start near the previous (converged) barrier parameter
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
}
IPOPT_INFEASIBLE = {"Infeasible_Problem_Detected"}
CERTIFIED_BY_SOCP, CERTIFIED_BY_IPOPT = "socp", "ipopt"


@dataclass(frozen=True)
class IpoptSolve:
    """One IPOPT run. `status` is IPOPT's return status; `x`, `lam_x`, `lam_g` the final
    primal/dual point (the next warm start); `objective_kw` the OPF's own losses (kW);
    `q_pu` the DER setpoints (p.u.)."""

    warm: bool
    success: bool
    status: str
    iterations: int
    solve_ms: float
    objective_kw: float
    q_pu: np.ndarray
    x: np.ndarray
    lam_x: np.ndarray
    lam_g: np.ndarray

    @property
    def infeasible(self) -> bool:
        return self.status in IPOPT_INFEASIBLE


def _sparse_dm(m: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi DM (no dense n×n intermediate)."""
    coo = sp.coo_matrix(m)
    return ca.DM.triplet(coo.row.tolist(), coo.col.tolist(), ca.DM(coo.data), coo.shape[0], coo.shape[1])


class AcOpf:
    """The polar AC OPF of one network, built once; `solve` per snapshot.

    Decision vector x = [θ (non-slack buses, rad), |V| (non-slack, p.u.), Q_DER (p.u.)].
    NLP parameters: fixed injections [P_fixed; Q_fixed] (2·n_bus, p.u.).
    Constraints g: the rows of `OpfProblem.balance` (P and Q mismatch at the non-slack
    buses = 0, then, with `slack_export=False`, the slack's P ≥ 0).
    """

    def __init__(self, net: Network, slack_export: bool = True):
        self.problem = problem = OpfProblem.of(net, slack_export)
        self.net, self.slack_export = net, slack_export
        n, n_der = net.n_bus, len(net.ders)
        self.others = problem.others
        m = self.others.size
        sym = ca.MX if n >= MX_MIN_BUSES else ca.SX
        theta_o, vm_o, q = sym.sym("theta", m), sym.sym("vm", m), sym.sym("q", n_der)
        p_fixed, q_fixed = sym.sym("p_fixed", n), sym.sym("q_fixed", n)
        place = _sparse_dm(incidence(self.others, n))  # non-slack values onto all buses
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
        mismatch_p = ca.mtimes(at_from, p_f) + ca.mtimes(at_to, p_t) + ca.DM(problem.gsh) * v2 - p_fixed
        mismatch_q = (
            ca.mtimes(at_from, q_f)
            + ca.mtimes(at_to, q_t)
            - ca.DM(problem.bsh) * v2
            - q_fixed
            - ca.mtimes(_sparse_dm(problem.der_at_bus), q)
        )
        rows = problem.balance(mismatch_p, mismatch_q, lambda e, i: e[i.tolist()])
        losses = mismatch_p[problem.slack] + ca.sum1(p_fixed) - ca.dot(ca.DM(problem.gsh), v2)
        nlp = {
            "x": ca.vertcat(theta_o, vm_o, q),
            "p": ca.vertcat(p_fixed, q_fixed),
            "f": problem.kw_per_pu * losses,
            "g": ca.vertcat(*(r.expr for r in rows)),
        }
        self._nlp = nlp
        self._solvers: dict[bool, ca.Function] = {}
        self._lbg = np.concatenate([r.lo for r in rows])
        self._ubg = np.concatenate([r.hi for r in rows])
        inf = np.full(m, np.inf)
        self._lbx_fixed = np.concatenate([-inf, problem.vm_min])
        self._ubx_fixed = np.concatenate([inf, problem.vm_max])
        self.flat_start = np.concatenate([np.zeros(m), np.ones(m), np.zeros(n_der)])

    def _solver(self, warm: bool) -> ca.Function:
        """The cold or warm IPOPT instance, created on first use (CasADi derives the
        NLP's Jacobian and Hessian per instance: seconds on a 10 000-bus feeder)."""
        if warm not in self._solvers:
            options = IPOPT_OPTIONS | WARM_OPTIONS if warm else IPOPT_OPTIONS
            self._solvers[warm] = ca.nlpsol("acopf_warm" if warm else "acopf_cold", "ipopt", self._nlp, options)
        return self._solvers[warm]

    def solve(self, s_fixed: np.ndarray, q_limit: np.ndarray, start: IpoptSolve | None = None) -> IpoptSolve:
        """Solve one snapshot: fixed injections `s_fixed` (n_bus,) complex p.u., usable Q
        limits `q_limit` (n_der,) p.u. With `start` (a previous solve) IPOPT is warm-started
        from its primal and dual point; without, it starts cold from the flat start."""
        args = {
            "p": np.concatenate([s_fixed.real, s_fixed.imag]),
            "lbx": np.concatenate([self._lbx_fixed, -q_limit]),
            "ubx": np.concatenate([self._ubx_fixed, q_limit]),
            "lbg": self._lbg,
            "ubg": self._ubg,
        }
        solver = self._solver(warm=start is not None)
        if start is None:
            out = solver(x0=self.flat_start, **args)
        else:
            out = solver(x0=start.x, lam_x0=start.lam_x, lam_g0=start.lam_g, **args)
        stats = solver.stats()
        x = np.asarray(out["x"]).ravel()
        return IpoptSolve(
            warm=start is not None,
            success=bool(stats["success"]),
            status=str(stats["return_status"]),
            iterations=int(stats["iter_count"]),
            solve_ms=float(stats["t_wall_total"]) * 1e3,
            objective_kw=float(out["f"]),
            q_pu=np.clip(x[2 * self.others.size :], -q_limit, q_limit),  # a no-op with bound_relax_factor 0
            x=x,
            lam_x=np.asarray(out["lam_x"]).ravel(),
            lam_g=np.asarray(out["lam_g"]).ravel(),
        )


def build_acopf(net: Network, slack_export: bool = True) -> AcOpf:
    """A new AC OPF of `net` (the caller's own: its IPOPT instances keep per-solve state)."""
    return AcOpf(net, slack_export)


def ac_opf(net: Network, slack_export: bool = True) -> AcOpf:
    """The AC OPF of `net`, built once per network and option in this thread."""
    return per_thread(net, ("acopf", bool(slack_export)), lambda: build_acopf(net, slack_export))


@dataclass
class _Snapshot:
    """How one snapshot was settled."""

    q_pu: np.ndarray
    status: str
    fallback: str
    attempts: list[IpoptSolve]
    socp: SocpSolve | None
    power_flows: int  # power flows the policy used to check points
    certified_by: str
    objective_kw: float = np.nan  # the point's losses where certified by the SOCP (kW)

    @property
    def accepted(self) -> IpoptSolve | None:
        return self.attempts[-1] if self.attempts and self.attempts[-1].success else None

    def diagnostics(self) -> dict:
        acc = self.accepted
        socp = (
            socp_diagnostics(self.socp)
            if self.socp
            else {"solve_ms": np.nan, "iterations": 0, "solver_status": "not-run", "relaxation_gap": np.nan}
        )
        by_socp = self.certified_by == CERTIFIED_BY_SOCP
        return {
            "solver_status": socp["solver_status"]
            if by_socp or not self.attempts
            else " → ".join(a.status for a in self.attempts),
            "iterations": sum(a.iterations for a in self.attempts),
            "solve_ms": socp["solve_ms"] if by_socp else sum(a.solve_ms for a in self.attempts),
            "warm_start": bool(self.attempts and self.attempts[0].warm),
            "objective_kw": self.objective_kw if by_socp else acc.objective_kw if acc else np.nan,
            "fallback": self.fallback,
            "certified_by": self.certified_by,
            "relaxation_gap": socp["relaxation_gap"],
            "socp_status": socp["solver_status"],
            "socp_ms": socp["solve_ms"],
        }


class _Policy:
    """Settles snapshots with IPOPT one by one under a failure policy, carrying the warm start."""

    def __init__(self, data: SnapshotData, problem: OpfProblem, fallback: Fallback, socp: tuple[SocpSolve, ...] | None):
        self.data, self.problem = data, problem
        self.fallback, self.socp = fallback, socp
        self.net = problem.net
        self.start: IpoptSolve | None = None

    @property
    def opf(self) -> AcOpf:
        return ac_opf(self.net, self.problem.slack_export)  # built on first use only

    def _relaxed(self, i: int) -> SocpSolve:
        if self.socp is not None:
            return self.socp[i]
        return relaxation(self.net, self.problem.slack_export).solve(self.data.s_fixed[i], self.data.q_limit[i])

    def _feasible(self, i: int, q_pu: np.ndarray) -> bool:
        s_fixed = self.data.s_fixed[i]
        s_mw = (s_fixed + 1j * (self.problem.der_at_bus @ q_pu)) * self.net.base_mva
        return bool(self.problem.feasible(solve_pf(self.net, s_mw), s_fixed)[0])

    def settle(self, i: int) -> _Snapshot:
        s_fixed, q_limit = self.data.s_fixed[i], self.data.q_limit[i]
        socp = self.socp[i] if self.socp is not None else None
        attempts = [self.opf.solve(s_fixed, q_limit, self.start)]
        if not attempts[-1].success and self.fallback == "chain" and self.start is not None:
            attempts.append(self.opf.solve(s_fixed, q_limit, None))
        if attempts[-1].success:
            self.start = attempts[-1]
            retried = len(attempts) > 1
            return _Snapshot(
                attempts[-1].q_pu,
                FALLBACK_COLD if retried else OK,
                FROM_COLD if retried else FROM_SOLVER,
                attempts,
                socp,
                0,
                CERTIFIED_BY_IPOPT,
            )
        flows = 0
        if self.fallback == "chain":
            socp = self._relaxed(i)
            if socp.optimal:
                flows += 1
                if self._feasible(i, socp.q_pu):
                    return _Snapshot(socp.q_pu, FALLBACK_SOCP, FROM_SOCP, attempts, socp, flows, "")
        no_action = np.zeros_like(q_limit)
        flows += 1
        if self._feasible(i, no_action):
            return _Snapshot(no_action, FALLBACK_NO_ACTION, FROM_NO_ACTION, attempts, socp, flows, "")
        shown = any(a.infeasible for a in attempts) or (socp is not None and socp.outcome == "infeasible")
        return _Snapshot(no_action, INFEASIBLE if shown else SOLVER_FAILED, FROM_NO_ACTION, attempts, socp, flows, "")


@dataclass(frozen=True)
class _FastPath:
    """The SOCP setpoints of every snapshot, AC-evaluated by one batched power flow."""

    q_pu: np.ndarray  # (S, n_der); zeros where the relaxation was not solved
    pf: PowerFlowResult
    certified: np.ndarray  # (S,) bool


def _fast_path(scenario: Scenario, problem: OpfProblem, data: SnapshotData, solves: tuple[SocpSolve, ...]) -> _FastPath:
    net = scenario.net
    n_der = len(net.ders)
    optimal = np.array([s.optimal for s in solves], dtype=bool)
    q_pu = np.array([s.q_pu if s.optimal else np.zeros(n_der) for s in solves]).reshape(len(solves), n_der)
    pf = solve_pf_batch(net, scenario.injections(q_pu * net.base_mva))
    bound = np.array([s.lower_bound_kw for s in solves])
    with np.errstate(invalid="ignore"):
        close = np.abs(pf.losses_kw - bound) <= CERTIFY_RTOL * np.abs(bound)
    return _FastPath(q_pu, pf, optimal & problem.feasible(pf, data.s_fixed) & close)


def _merge(fast: PowerFlowResult, rest: PowerFlowResult, rows: np.ndarray) -> PowerFlowResult:
    """`fast` with the snapshots `rows` replaced by `rest`'s (in order)."""
    v, conv, it = fast.v.copy(), np.array(fast.converged, copy=True), np.array(fast.iterations, copy=True)
    v[rows], conv[rows], it[rows] = rest.v, rest.converged, rest.iterations
    return PowerFlowResult(fast.net, v, conv, it)


def run_acopf(
    scenario: Scenario,
    k: float,
    *,
    slack_export: bool = True,
    fallback: Fallback = "chain",
    lower_bound: bool = True,
    solver: Solver = "auto",
) -> StrategyResult:
    """AC OPF on every snapshot of `scenario` with reserve k (see the module docstring).

    Returns the setpoints evaluated by the AC power flow, with status per snapshot and
    lower_bound_kw from the SOCP relaxation (NaN where it was not solved). extra (per
    snapshot): certified_by ("socp" | "ipopt" | "" where neither certified the point),
    solver_status (IPOPT's return status of each attempt, "a → b"; Clarabel's where
    certified by the SOCP), iterations (IPOPT's, summed over attempts; 0 where certified
    by the SOCP), solve_ms (the certifying solver's time: IPOPT's summed over attempts,
    or the SOCP solve's), warm_start, objective_kw (the OPF's own losses, NaN unless
    certified), fallback, relaxation_gap / socp_status / socp_ms (the relaxation solve),
    ac_feasible (the reported point meets every limit).
    """
    check_option("AC OPF failure policy", fallback, FALLBACKS)
    check_option("AC OPF solver", solver, SOLVERS)
    start = now()
    net = scenario.net
    data = snapshot_data(scenario, k)
    problem = OpfProblem.of(net, slack_export)
    fast_path = solver == "auto"
    solves = socp_solves(scenario, k, slack_export, data=data) if lower_bound or fast_path else None
    n = data.n_snapshots
    fast = _fast_path(scenario, problem, data, solves) if fast_path else None
    certified = fast.certified if fast else np.zeros(n, dtype=bool)
    policy = _Policy(data, problem, fallback, solves)
    settled = []
    for i in range(n):
        if certified[i]:
            settled.append(
                _Snapshot(fast.q_pu[i], OK, FROM_SOLVER, [], solves[i], 0, CERTIFIED_BY_SOCP, float(fast.pf.losses_kw[i]))
            )
        elif fast_path and solves[i].outcome == "infeasible":  # the relaxation proves it: no IPOPT
            settled.append(_Snapshot(np.zeros(len(net.ders)), INFEASIBLE, FROM_NO_ACTION, [], solves[i], 1, ""))
        else:
            s = policy.settle(i)
            s.power_flows += int(fast_path)  # the fast path's flow; a certified one's is its evaluation
            settled.append(s)
    q_pu = np.array([s.q_pu for s in settled]).reshape(n, len(net.ders))
    pf = None
    if fast is not None:  # the certified snapshots' evaluation is done; evaluate the rest
        rows = np.flatnonzero(~certified)
        pf = (
            fast.pf
            if rows.size == 0
            else _merge(fast.pf, solve_pf_batch(net, scenario.take(rows).injections(q_pu[rows] * net.base_mva)), rows)
        )
    return evaluated_result(
        "acopf",
        k,
        scenario,
        problem,
        data,
        q_pu,
        elapsed_ms(start),
        status=np.array([s.status for s in settled], dtype=object),
        lower_bound_kw=np.array([s.socp.lower_bound_kw if s.socp else np.nan for s in settled]),
        extra=diagnostics(s.diagnostics() for s in settled),
        power_flows=np.array([s.power_flows for s in settled]),
        pf=pf,
    )
