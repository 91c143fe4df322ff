"""The `acopf` strategy: the centralized AC OPF (`models.polar_ac`, IPOPT) on every snapshot
of a scenario, with the certified fast path through the SOCP relaxation and a recorded
failure policy (`policy`).

With `solver="auto"` (default) the interval bounds (`infeasibility`) and the relaxation
(`relaxation.socp_solves`, shared by data with the `socp` strategy; not solved where the
bounds prove infeasibility) settle what they can — certified optima, proven
infeasibility — and IPOPT solves only the other snapshots; `solver="ipopt"` solves every snapshot with
IPOPT (the paper's question is how often a nonlinear OPF solver fails: `opfbench run
--acopf-solver ipopt` answers it for `acopf` and `acopf-paper`). Either way the
relaxation's optimum is the result's `lower_bound_kw`, which certifies the optimality gap
of every strategy on the snapshot.
"""

from __future__ import annotations

import numpy as np

from opfbench.formulations.infeasibility import proven_infeasible
from opfbench.formulations.options import ACOPF_SOLVERS, FALLBACKS, AcopfSolver, Fallback, check_option
from opfbench.formulations.policy import IpoptPolicy, fast_path, merge_flows
from opfbench.formulations.problem import OpfProblem, snapshot_data
from opfbench.formulations.relaxation import socp_solves
from opfbench.formulations.results import diagnostics, evaluated_result
from opfbench.powerflow import solve_pf_batch
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now


def run_acopf(
    scenario: Scenario,
    k: float,
    *,
    slack_export: bool = True,
    fallback: Fallback = "chain",
    solver: AcopfSolver = "auto",
    curtail: bool = False,
) -> StrategyResult:
    """AC OPF on every snapshot of `scenario` with reserve k (see the module docstring);
    `curtail`: the optimum may curtail the DER's active power at the cost of the power
    curtailed (`formulations.curtail`).

    Returns the setpoints evaluated by the AC power flow, with status per snapshot and
    lower_bound_kw from the SOCP relaxation (NaN where it was not solved, or where the
    point is not feasible). extra (per snapshot): certified_by ("socp" | "ipopt" | ""
    where neither certified the point), solver_status (IPOPT's return status of each
    attempt, "a → b"; Clarabel's where certified by the SOCP; the bounds' reason where
    they prove infeasibility, `infeasibility.SLACK_MUST_EXPORT` or
    `VOLTAGES_OUT_OF_REACH`), iterations (IPOPT's, summed over attempts; 0 where certified
    by the SOCP), solve_ms (the certifying solver's time: IPOPT's summed over attempts,
    or the SOCP solve's), warm_start, objective_kw (the OPF's own losses, NaN unless
    certified), fallback, relaxation_gap / socp_status / socp_ms (the relaxation solve;
    NaN / "" / 0 where not solved),
    ac_feasible (the reported point meets every limit).
    """
    check_option("AC OPF failure policy", fallback, FALLBACKS)
    check_option("AC OPF solver", solver, ACOPF_SOLVERS)
    if curtail:
        from opfbench.formulations.curtail import run_curtailing

        return run_curtailing(scenario, k, slack_export=slack_export, fallback=fallback, solver=solver)
    start = now()
    net = scenario.net
    data = snapshot_data(scenario, k)
    problem = OpfProblem.of(net, slack_export)
    fast = None
    if solver == "auto":
        proofs = proven_infeasible(problem, data)
        solves = socp_solves(scenario, k, slack_export, data=data, skip=proofs != "")
        fast = fast_path(scenario, problem, data, solves, proofs)
    else:
        solves = socp_solves(scenario, k, slack_export, data=data)
    n = data.n_snapshots
    policy = IpoptPolicy(data, problem, fallback, solves)
    settled = []
    for i in range(n):
        s = fast.settled(i, solves[i]) if fast is not None else None
        if s is None:
            s = policy.settle(i)
            s.power_flows += int(fast is not None)  # the fast path's flow; a certified one's is its evaluation
        settled.append(s)
    q_pu = np.array([s.q_pu for s in settled]).reshape(n, len(net.ders))
    pf = None
    if fast is not None:  # the certified snapshots' evaluation is done; evaluate the rest
        rows = np.flatnonzero(~fast.certified)
        pf = (
            fast.pf
            if rows.size == 0
            else merge_flows(fast.pf, solve_pf_batch(net, scenario.take(rows).injections(q_pu[rows] * net.base_mva)), rows)
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
        lower_bound_kw=np.array([s.socp.lower_bound_kw for s in settled]),
        extra=diagnostics(s.diagnostics() for s in settled),
        power_flows=np.array([s.power_flows for s in settled]),
        pf=pf,
    )
