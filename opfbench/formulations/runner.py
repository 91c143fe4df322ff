"""The one runner of every formulation model: the model's setpoints on every snapshot of a
scenario, AC-evaluated, with statuses, the fallback chain and certification
(`model` says what a model is; `evaluation` builds the one result record).

- An exact model (`run_exact`, the OPF problem's exact model behind `acopf`): with
  `solver="auto"` (default) the interval bounds (`infeasibility`) and the OPF problem's
  relaxation (`solves.relaxation_solves`, shared by data with the `socp` strategy; not
  solved where the bounds prove infeasibility) settle what they can — certified optima,
  proven infeasibility — and the exact model solves only the other snapshots, under the
  failure policy (`policy`: warm → cold → the relaxation's point → no action, or the
  paper's); `solver="ipopt"` solves every snapshot with the exact model (the paper's
  question is how often a nonlinear OPF solver fails: `opfbench run --acopf-solver ipopt`
  answers it for `acopf` and `acopf-paper`). Either way the relaxation's optimum is the
  result's `lower_bound_kw`, which certifies the optimality gap of every strategy on the
  snapshot.
- A relaxation or an approximation (`run_batch`): its solves (`solves.model_solves`,
  shared by data); status "ok" where it solved, "infeasible" where the solver certified
  infeasibility (then no action, Q = 0 — for a relaxation this also proves the AC OPF
  infeasible), "solver-failed" otherwise (also Q = 0). A relaxation's optimum is the
  result's `lower_bound_kw`; an approximation's is its `SolverRecord.objective_kw`, an
  estimate the AC evaluation measures.

`run_model` runs any registered model by its role.
"""

from __future__ import annotations

import numpy as np

from opfbench.formulations.acopf_options import ACOPF_SOLVERS, FALLBACKS, AcopfSolver, Fallback, check_option
from opfbench.formulations.evaluation import evaluated_result, solver_record
from opfbench.formulations.infeasibility import proven_infeasible
from opfbench.formulations.model import built, model_for
from opfbench.formulations.policy import IpoptPolicy, fast_path, merge_flows
from opfbench.formulations.problem import OpfProblem, snapshot_data
from opfbench.formulations.solves import model_solves, relaxation_solves
from opfbench.formulations.three_phase import run_phase, run_phase_batch
from opfbench.powerflow import solve_pf_batch
from opfbench.registry.specs import ModelSpec, Role
from opfbench.result import FROM_NO_ACTION, FROM_SOLVER, INFEASIBLE, OK, SOLVER_FAILED, StrategyResult
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now


def run_model(
    model: ModelSpec,
    scenario: Scenario,
    k: float,
    *,
    name: str = "",
    slack_export: bool = True,
    fallback: Fallback = "chain",
    solver: AcopfSolver = "auto",
) -> StrategyResult:
    """`model` on every snapshot of `scenario` with reserve k (module docstring), the result
    named `name` (default: the model's); `fallback` and `solver` apply to an exact model —
    on a three-phase feeder `three_phase.run_phase`: IPOPT on every snapshot, and with
    `solver` "auto" the relaxation's bound on a sample of them (`three_phase.BOUND_SAMPLE`),
    which certifies the optimum where it closes the gap ("ipopt": no bound) — and
    `three_phase.run_phase_batch` for a model of another role."""
    if scenario.three_phase and model.role == "exact":
        check_option("AC OPF solver", solver, ACOPF_SOLVERS)
        return run_phase(model, scenario, k, name=name, slack_export=slack_export, fallback=fallback, bounded=solver == "auto")
    if scenario.three_phase:
        return run_phase_batch(model, scenario, k, name=name, slack_export=slack_export)
    if model.role == "exact":
        return run_exact(model, scenario, k, name=name, slack_export=slack_export, fallback=fallback, solver=solver)
    return run_batch(model, scenario, k, name=name, slack_export=slack_export)


def run_exact(
    model: ModelSpec,
    scenario: Scenario,
    k: float,
    *,
    name: str = "",
    slack_export: bool = True,
    fallback: Fallback = "chain",
    solver: AcopfSolver = "auto",
) -> StrategyResult:
    """An exact model on every snapshot (module docstring), the result named `name`
    (default: the model's).

    Returns the setpoints evaluated by the AC power flow, with status per snapshot and
    lower_bound_kw from the relaxation (NaN where it was not solved, or where the point is
    not feasible). The solver record (per snapshot): certified_by ("socp" | "ipopt" | ""
    where neither certified the point), solver_status (IPOPT's return status of each
    attempt, "a → b"; Clarabel's where certified by the relaxation; the bounds' reason
    where they prove infeasibility, `infeasibility.SLACK_MUST_EXPORT` or
    `VOLTAGES_OUT_OF_REACH`), iterations (IPOPT's, summed over attempts; 0 where certified
    by the relaxation), solve_ms (the certifying solver's time: IPOPT's summed over
    attempts, or the relaxation solve's), objective_kw (the OPF's own losses, NaN unless
    certified), fallback. extra: warm_start, relaxation_gap / socp_status / socp_ms (the
    relaxation solve; NaN / "" / 0 where not solved), ac_feasible (the reported point
    meets every limit).
    """
    check_option("AC OPF failure policy", fallback, FALLBACKS)
    check_option("AC OPF solver", solver, ACOPF_SOLVERS)
    start = now()
    net = scenario.net
    data = snapshot_data(scenario, k)
    problem = OpfProblem.of(net, slack_export)
    fast = None
    if solver == "auto":
        proofs = proven_infeasible(problem, data)
        solves = relaxation_solves(scenario, k, slack_export, data=data, skip=proofs != "")
        fast = fast_path(scenario, problem, data, solves, proofs)
    else:
        solves = relaxation_solves(scenario, k, slack_export, data=data)
    n = data.n_snapshots
    policy = IpoptPolicy(data, problem, fallback, solves, lambda: built(model, net, slack_export))
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
    record, extra = solver_record(model, [s.diagnostics() for s in settled])
    return evaluated_result(
        name or model.name,
        k,
        scenario,
        problem,
        data,
        q_pu,
        elapsed_ms(start),
        status=np.array([s.status for s in settled], dtype=object),
        lower_bound_kw=np.array([s.socp.objective_kw for s in settled]),
        solver=record,
        extra=extra,
        power_flows=np.array([s.power_flows for s in settled]),
        pf=pf,
    )


def run_batch(model: ModelSpec, scenario: Scenario, k: float, *, name: str = "", slack_export: bool = True) -> StrategyResult:
    """A relaxation or approximation on every snapshot, its setpoints evaluated by the AC
    power flow (module docstring), the result named `name` (default: the model's). lower_bound_kw: a relaxation's optimum (NaN where not
    solved; an approximation gives none). The solver record: solve_ms, iterations,
    solver_status (Clarabel's), objective_kw (the model's optimum), fallback, certified_by
    ("" — the model's point is not certified optimal for the AC OPF; `run_exact` does
    that); extra: solves, and a relaxation's relaxation_gap.
    """
    start = now()
    data = snapshot_data(scenario, k)
    net = scenario.net
    solves = model_solves(model, net, data, slack_export)
    n_der = len(net.ders)
    q_pu = np.array([s.q_pu if s.q_pu is not None else np.zeros(n_der) for s in solves]).reshape(len(solves), n_der)
    status = np.array([OK if s.optimal else INFEASIBLE if s.infeasible else SOLVER_FAILED for s in solves], dtype=object)
    relaxation = model.role == "relaxation"
    rows = []
    for s in solves:
        row = s.diagnostics() | {"fallback": FROM_SOLVER if s.optimal else FROM_NO_ACTION, "certified_by": ""}
        rows.append(row | {"objective_kw": s.objective_kw} | ({"relaxation_gap": s.relaxation_gap} if relaxation else {}))
    record, extra = solver_record(model, rows)
    objective = np.array([s.objective_kw for s in solves])
    return evaluated_result(
        name or model.name,
        k,
        scenario,
        OpfProblem.of(net, slack_export),
        data,
        q_pu,
        elapsed_ms(start),
        status,
        objective if relaxation else None,
        solver=record,
        extra=extra,
    )


def run_problem_model(role: Role, name: str, scenario: Scenario, k: float, **options) -> StrategyResult:
    """The OPF problem's model of `role` on the scenario's network (`model.model_for`), the
    result named `name`."""
    return run_model(model_for(role, scenario.net), scenario, k, name=name, **options)
