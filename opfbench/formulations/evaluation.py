"""From a formulation's per-snapshot answers to the one result record (`StrategyResult`):
the per-snapshot diagnostics → the typed solver record (`result.SolverRecord`) and the
model's other diagnostics (`extra`), and the AC evaluation every formulation's setpoints
get. Statuses and the vocabularies of `fallback` and `certified_by` are `opfbench.result`'s.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from opfbench.formulations.problem import OpfProblem, SnapshotData
from opfbench.powerflow import PowerFlowResult, solve_pf_batch
from opfbench.registry.specs import ModelSpec
from opfbench.result import SolverRecord, StrategyResult
from opfbench.scenario import Scenario


def diagnostics(rows: Iterable[dict]) -> dict[str, np.ndarray]:
    """Per-snapshot diagnostic dicts (same keys) → one array per key for `StrategyResult.extra`
    (bool, int64, object for strings, float otherwise)."""
    rows = list(rows)
    out: dict[str, np.ndarray] = {}
    for key in rows[0] if rows else ():
        values = [r[key] for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in values):
            out[key] = np.array(values, dtype=bool)
        elif all(isinstance(v, (int, np.integer)) for v in values):
            out[key] = np.array(values, dtype=np.int64)
        elif all(isinstance(v, str) for v in values):
            out[key] = np.array(values, dtype=object)
        else:
            out[key] = np.array(values, dtype=float)
    return out


def solver_record(model: ModelSpec, rows: Iterable[dict]) -> tuple[SolverRecord, dict[str, np.ndarray]]:
    """Per-snapshot diagnostic dicts (same keys, with at least the record's: objective_kw,
    solver_status, fallback, certified_by, solve_ms, iterations) → the typed record of
    `model`'s answers, and the other keys as `extra` arrays (`diagnostics`)."""
    columns = diagnostics(rows)
    typed = ("objective_kw", "solver_status", "fallback", "certified_by", "solve_ms", "iterations")
    record = SolverRecord(model.name, model.meaning, *(columns.pop(key, np.zeros(0)) for key in typed))
    return record, columns


def evaluated_result(
    strategy: str,
    k: float,
    scenario: Scenario,
    problem: OpfProblem,
    data: SnapshotData,
    q_pu: np.ndarray,
    wall_ms: float,
    status: np.ndarray,
    lower_bound_kw: np.ndarray | None,
    solver: SolverRecord,
    extra: dict[str, np.ndarray],
    power_flows: np.ndarray | int = 0,
    pf: PowerFlowResult | None = None,
    p_pu: np.ndarray | None = None,
) -> StrategyResult:
    """A formulation's result: setpoints `q_pu` (S, n_der) — with the DER's active power
    `p_pu` (S, n_der) where the formulation curtails — evaluated by the batched AC power
    flow (or `pf`, that evaluation already done), with extra["ac_feasible"] (the point
    meets every limit, `OpfProblem.feasible`) and the scalar extra["slack_export"].

    `lower_bound_kw` (the relaxation's, per snapshot; None for a model that gives none)
    bounds the losses of the points that meet the limits, so the result carries it only
    where its own point does; elsewhere (no feasible point found: infeasible,
    solver-failed, a point applied anyway under the paper's policy) the bound is NaN there
    and kept as extra["relaxation_bound_kw"]."""
    net = scenario.net
    q_mvar = np.asarray(q_pu, dtype=float).reshape(scenario.n_snapshots, len(net.ders)) * net.base_mva
    p_mw = None if p_pu is None else np.asarray(p_pu, dtype=float).reshape(q_mvar.shape) * net.base_mva
    if pf is None:
        pf = solve_pf_batch(net, scenario.injections(q_mvar, p_mw))
    feasible = problem.feasible(pf, data.s_fixed)
    full: dict[str, object] = {**extra, "ac_feasible": feasible, "slack_export": problem.slack_export}
    if lower_bound_kw is not None:
        full["relaxation_bound_kw"] = lower_bound_kw
        lower_bound_kw = np.where(feasible, lower_bound_kw, np.nan)
    flows = np.asarray(power_flows, dtype=np.int64) + 1
    return StrategyResult.from_setpoints(
        strategy,
        k,
        scenario,
        q_mvar,
        wall_ms,
        power_flows=flows,
        pf=pf,
        status=status,
        lower_bound_kw=lower_bound_kw,
        solver=solver,
        extra=full,
        p_mw=p_mw,
    )
