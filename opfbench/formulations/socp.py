"""The `socp` strategy: the SOCP relaxation's setpoints (`relaxation`: DistFlow on radial
feeders, Jabr on meshed ones, Clarabel), evaluated by the AC power flow; its optimum is a
certified lower bound on the achievable losses."""

from __future__ import annotations

import numpy as np

from opfbench.formulations.problem import OpfProblem, snapshot_data
from opfbench.formulations.results import FROM_NO_ACTION, FROM_SOLVER, diagnostics, evaluated_result
from opfbench.formulations.solves import model_of, socp_solves
from opfbench.result import INFEASIBLE, OK, SOLVER_FAILED, StrategyResult
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now


def run_socp(scenario: Scenario, k: float, *, slack_export: bool = True) -> StrategyResult:
    """The relaxation's setpoints on every snapshot, evaluated by the AC power flow.

    Status "ok" where Clarabel solved it, "infeasible" where it certified infeasibility
    (then no action, Q = 0, which also proves the AC OPF infeasible), "solver-failed"
    otherwise (also Q = 0). lower_bound_kw: the relaxation bound (NaN where not solved).
    extra: solve_ms, iterations, solves, solver_status (Clarabel's), relaxation_gap, fallback,
    certified_by ("" — the relaxation's point is not certified optimal for the AC OPF;
    `run_acopf` does that), model ("distflow" or "jabr").
    """
    start = now()
    data = snapshot_data(scenario, k)
    model = model_of(scenario.net).model
    solves = socp_solves(scenario, k, slack_export, data)
    n_der = len(scenario.net.ders)
    q_pu = np.array([s.q_pu if s.q_pu is not None else np.zeros(n_der) for s in solves]).reshape(len(solves), n_der)
    status = np.array([OK if s.optimal else INFEASIBLE if s.infeasible else SOLVER_FAILED for s in solves], dtype=object)
    extra = diagnostics(
        s.diagnostics() | {"fallback": FROM_SOLVER if s.optimal else FROM_NO_ACTION, "certified_by": "", "model": model}
        for s in solves
    )
    return evaluated_result(
        "socp",
        k,
        scenario,
        OpfProblem.of(scenario.net, slack_export),
        data,
        q_pu,
        elapsed_ms(start),
        status,
        np.array([s.lower_bound_kw for s in solves]),
        extra,
    )
