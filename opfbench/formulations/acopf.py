"""Centralized AC OPF (polar form, CasADi + IPOPT) with a recorded failure policy.

Problem per snapshot (per unit on `net.base_mva`):

    minimize    branch losses = P_slack + Σ P_fixed − Σ Gsh·|V|²   (= slack P + DER P − load P
                                                                    when there are no bus shunts)
    over        Q of every DER, |V| and θ of every non-slack bus
    subject to  AC power balance at every non-slack bus (π model, `common.PiBranches`),
                |V_slack| = net.v_slack, θ_slack = 0, vmin ≤ |V| ≤ vmax elsewhere,
                −(1 − k)·Qmax(P) ≤ Q ≤ (1 − k)·Qmax(P) with DER P fixed,
                slack P ≥ 0 if `slack_export=False` (the paper's/pandapower's setup).

`AcOpf` builds the NLP once per (network, slack_export) — fixed injections are NLP
parameters, Q limits are variable bounds — with two IPOPT instances: a cold one (flat
start, IPOPT's defaults) and a warm one (primal and dual start from a previous solution,
`warm_start_init_point`, small initial barrier). Every solve returns its status,
iterations and time from IPOPT's statistics.

`run_acopf` solves every snapshot of a scenario in order, warm-starting each from the
last successful solution, and applies a failure policy, recorded per snapshot:

- `chain` (default): warm IPOPT → cold IPOPT → the SOCP relaxation's setpoints if, AC
  evaluated, they are feasible → no action if feasible. Status "ok" / "fallback-cold" /
  "fallback-socp" / "fallback-no-action".
- `paper`: IPOPT once (warm when possible); on failure, no action — as the paper did.

When no point is found feasible, the setpoints are those of no action (extra["fallback"]
= "no-action", its AC losses reported) and the status is "infeasible" if IPOPT reported
infeasibility or the SOCP relaxation is infeasible (which proves it), "solver-failed"
otherwise. The SOCP relaxation is also solved for every snapshot (`lower_bound=True`,
default): its optimum is the result's `lower_bound_kw`, which certifies the optimality
gap of the OPF and of every other strategy on the same snapshot.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import casadi as ca
import numpy as np

from opfbench.errors import InputError
from opfbench.formulations.common import (
    FALLBACK_COLD,
    FALLBACK_NO_ACTION,
    FALLBACK_SOCP,
    FROM_COLD,
    FROM_NO_ACTION,
    FROM_SOCP,
    FROM_SOLVER,
    SOLVER_FAILED,
    PiBranches,
    SnapshotData,
    ac_feasible,
    bus_shunts,
    check_supported,
    diagnostics,
    evaluated_result,
    incidence,
    kw_per_pu,
    snapshot_data,
)
from opfbench.formulations.socp import SocpRelaxation, SocpSolve, build_socp, socp_diagnostics
from opfbench.network import Network
from opfbench.powerflow import solve_pf
from opfbench.result import INFEASIBLE, OK, StrategyResult
from opfbench.scenario import Scenario

Fallback = Literal["chain", "paper"]
FALLBACKS = ("chain", "paper")

TOLERANCE = 1e-10  # IPOPT tol (scaled NLP error; objective in kW)
# IPOPT's gradient-based scaling shrinks the kW objective; without this extra factor the
# barrier left active Q bounds ~3e-6 MVAr short, ~1e-5 relative above the optimum on
# case69-der (seen against the exact SOCP bound). With it: ≤ 1e-6, and fewer iterations.
OBJECTIVE_SCALING = 100.0
MAX_ITER = 300
IPOPT_OPTIONS = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "record_time": True,
    "ipopt.tol": TOLERANCE,
    "ipopt.obj_scaling_factor": OBJECTIVE_SCALING,
    "ipopt.max_iter": MAX_ITER,
    # The KKT systems are tiny: skip MUMPS' scaling and use AMD ordering (≈10 % faster).
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


@dataclass(frozen=True)
class IpoptSolve:
    """One IPOPT run. `status` is IPOPT's return status; `x`, `lam_x`, `lam_g` the final
    primal/dual point (the next warm start); `objective_kw` the OPF's own losses (kW);
    `q_pu` the DER setpoints (p.u.), clipped to the Q limits (IPOPT's `bound_relax_factor`
    lets the iterate exceed a bound by ~1e-8 relative)."""

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


class AcOpf:
    """The polar AC OPF of one network, built once; `solve` per snapshot.

    Decision vector x = [θ (non-slack buses, rad), |V| (non-slack, p.u.), Q_DER (p.u.)].
    NLP parameters: fixed injections [P_fixed; Q_fixed] (2·n_bus, p.u.).
    Constraints g = [P mismatch; Q mismatch] at the non-slack buses (= 0), then, with
    `slack_export=False`, the slack's P (≥ 0).
    """

    def __init__(self, net: Network, slack_export: bool = True):
        check_supported(net)
        self.net, self.slack_export = net, slack_export
        n, n_der = net.n_bus, len(net.ders)
        self.others = np.flatnonzero(np.arange(n) != net.slack)
        m = self.others.size
        theta_o, vm_o, q = ca.SX.sym("theta", m), ca.SX.sym("vm", m), ca.SX.sym("q", n_der)
        p_fixed, q_fixed = ca.SX.sym("p_fixed", n), ca.SX.sym("q_fixed", n)
        theta, vm = ca.SX.zeros(n), ca.SX.zeros(n)
        theta[self.others.tolist()] = theta_o
        vm[self.others.tolist()] = vm_o
        vm[net.slack] = net.v_slack

        br = PiBranches.of(net)
        f, t = br.f.tolist(), br.t.tolist()
        vv = vm[f] * vm[t]
        c, s = vv * ca.cos(theta[f] - theta[t]), vv * ca.sin(theta[f] - theta[t])
        v2 = vm**2
        p_f, q_f, p_t, q_t = br.flows(v2[f], v2[t], c, s, lambda a, e: ca.DM(a) * e)
        at_from, at_to = ca.DM(br.at_from), ca.DM(br.at_to)
        gsh, bsh = bus_shunts(net)
        mismatch_p = ca.mtimes(at_from, p_f) + ca.mtimes(at_to, p_t) + ca.DM(gsh) * v2 - p_fixed
        mismatch_q = (ca.mtimes(at_from, q_f) + ca.mtimes(at_to, q_t) - ca.DM(bsh) * v2 - q_fixed
                      - ca.mtimes(ca.DM(incidence(net.der_bus, n)), q))
        others = self.others.tolist()
        g = [mismatch_p[others], mismatch_q[others]]
        slack_p = mismatch_p[net.slack]  # what the external grid injects
        if not slack_export:
            g.append(slack_p)
        losses = slack_p + ca.sum1(p_fixed) - ca.dot(ca.DM(gsh), v2)
        nlp = {"x": ca.vertcat(theta_o, vm_o, q), "p": ca.vertcat(p_fixed, q_fixed),
               "f": kw_per_pu(net) * losses, "g": ca.vertcat(*g)}
        self._cold = ca.nlpsol("acopf_cold", "ipopt", nlp, IPOPT_OPTIONS)
        self._warm = ca.nlpsol("acopf_warm", "ipopt", nlp, IPOPT_OPTIONS | WARM_OPTIONS)
        n_g = 2 * m + (0 if slack_export else 1)
        self._lbg = np.zeros(n_g)
        self._ubg = np.zeros(n_g)
        if not slack_export:
            self._ubg[-1] = np.inf
        inf = np.full(m, np.inf)
        self._lbx_fixed = np.concatenate([-inf, net.vmin[self.others]])
        self._ubx_fixed = np.concatenate([inf, net.vmax[self.others]])
        self.flat_start = np.concatenate([np.zeros(m), np.ones(m), np.zeros(n_der)])

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
        if start is None:
            solver = self._cold
            out = solver(x0=self.flat_start, **args)
        else:
            solver = self._warm
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
            q_pu=np.clip(x[2 * self.others.size:], -q_limit, q_limit),  # IPOPT relaxes bounds by ~1e-8
            x=x,
            lam_x=np.asarray(out["lam_x"]).ravel(),
            lam_g=np.asarray(out["lam_g"]).ravel(),
        )


@lru_cache(maxsize=16)
def build_acopf(net: Network, slack_export: bool = True) -> AcOpf:
    """The AC OPF of `net` (cached per network object and option)."""
    return AcOpf(net, slack_export)


@dataclass
class _Snapshot:
    """How one snapshot was settled."""

    q_pu: np.ndarray
    status: str
    fallback: str
    attempts: list[IpoptSolve]
    socp: SocpSolve | None
    power_flows: int  # power flows the policy used to check fallback points

    @property
    def accepted(self) -> IpoptSolve | None:
        return self.attempts[-1] if self.attempts[-1].success else None

    def diagnostics(self) -> dict:
        acc = self.accepted
        socp = socp_diagnostics(self.socp) if self.socp else {"solve_ms": np.nan, "iterations": 0,
                                                                "solver_status": "not-run", "relaxation_gap": np.nan}
        return {
            "solver_status": " → ".join(a.status for a in self.attempts),
            "iterations": sum(a.iterations for a in self.attempts),
            "solve_ms": sum(a.solve_ms for a in self.attempts),
            "warm_start": self.attempts[0].warm,
            "objective_kw": acc.objective_kw if acc else np.nan,
            "fallback": self.fallback,
            "relaxation_gap": socp["relaxation_gap"],
            "socp_status": socp["solver_status"],
            "socp_ms": socp["solve_ms"],
        }


class _Policy:
    """Settles snapshots one by one under a failure policy, carrying the warm start."""

    def __init__(self, net: Network, data: SnapshotData, slack_export: bool, fallback: Fallback, lower_bound: bool):
        self.net, self.data, self.slack_export = net, data, slack_export
        self.fallback, self.lower_bound = fallback, lower_bound
        self.opf = build_acopf(net, slack_export)
        self.start: IpoptSolve | None = None
        self._der_at_bus = incidence(net.der_bus, net.n_bus)

    def _relaxation(self) -> SocpRelaxation:
        return build_socp(self.net, self.slack_export)

    def _feasible(self, i: int, q_pu: np.ndarray) -> bool:
        s_fixed = self.data.s_fixed[i]
        s_mw = (s_fixed + 1j * (self._der_at_bus @ q_pu)) * self.net.base_mva
        return bool(ac_feasible(self.net, solve_pf(self.net, s_mw), s_fixed, self.slack_export)[0])

    def settle(self, i: int) -> _Snapshot:
        s_fixed, q_limit = self.data.s_fixed[i], self.data.q_limit[i]
        attempts = [self.opf.solve(s_fixed, q_limit, self.start)]
        if not attempts[-1].success and self.fallback == "chain" and self.start is not None:
            attempts.append(self.opf.solve(s_fixed, q_limit, None))
        socp = self._relaxation().solve(s_fixed, q_limit) if self.lower_bound else None
        if attempts[-1].success:
            self.start = attempts[-1]
            retried = len(attempts) > 1
            return _Snapshot(attempts[-1].q_pu, FALLBACK_COLD if retried else OK,
                             FROM_COLD if retried else FROM_SOLVER, attempts, socp, 0)
        flows = 0
        if self.fallback == "chain":
            socp = socp or self._relaxation().solve(s_fixed, q_limit)
            if socp.optimal:
                flows += 1
                if self._feasible(i, socp.q_pu):
                    return _Snapshot(socp.q_pu, FALLBACK_SOCP, FROM_SOCP, attempts, socp, flows)
        no_action = np.zeros_like(q_limit)
        flows += 1
        if self._feasible(i, no_action):
            return _Snapshot(no_action, FALLBACK_NO_ACTION, FROM_NO_ACTION, attempts, socp, flows)
        shown = any(a.infeasible for a in attempts) or (socp is not None and socp.outcome == "infeasible")
        return _Snapshot(no_action, INFEASIBLE if shown else SOLVER_FAILED, FROM_NO_ACTION, attempts, socp, flows)


def run_acopf(scenario: Scenario, k: float, *, slack_export: bool = True, fallback: Fallback = "chain",
              lower_bound: bool = True) -> StrategyResult:
    """AC OPF on every snapshot of `scenario` (in order, warm-started) with reserve k.

    Returns the setpoints evaluated by the AC power flow, with status and
    extra["fallback"] per snapshot as described in the module docstring, and
    lower_bound_kw from the SOCP relaxation (NaN where it was not solved). extra:
    solver_status (IPOPT's return status of each attempt, "a → b"), iterations and
    solve_ms (summed over the attempts), warm_start, objective_kw (the OPF's own
    losses, NaN unless IPOPT solved it), fallback, relaxation_gap / socp_status /
    socp_ms (the relaxation solve), ac_feasible (the reported point meets every limit).
    """
    if fallback not in FALLBACKS:
        raise InputError(f"unknown AC OPF failure policy {fallback!r}; choose {' or '.join(FALLBACKS)}")
    start = time.perf_counter()
    net = scenario.net
    data = snapshot_data(scenario, k)
    policy = _Policy(net, data, slack_export, fallback, lower_bound)
    settled = [policy.settle(i) for i in range(data.n_snapshots)]
    wall_ms = (time.perf_counter() - start) * 1e3
    return evaluated_result(
        "acopf", k, scenario, data, np.array([s.q_pu for s in settled]), slack_export, wall_ms,
        status=np.array([s.status for s in settled], dtype=object),
        lower_bound_kw=np.array([s.socp.lower_bound_kw if s.socp else np.nan for s in settled]),
        extra=diagnostics(s.diagnostics() for s in settled),
        power_flows=np.array([s.power_flows for s in settled]))
