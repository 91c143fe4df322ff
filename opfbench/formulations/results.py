"""From a formulation's per-snapshot answers to the one result record (`StrategyResult`).

The vocabulary of `extra["fallback"]` (which point a snapshot's setpoints come from) and
`extra["certified_by"]` (which solver proved the point optimal), the per-snapshot
diagnostics → arrays conversion, and the AC evaluation every formulation's setpoints get.
Statuses are `opfbench.result`'s.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from opfbench.formulations.problem import OpfProblem, SnapshotData
from opfbench.powerflow import PowerFlowResult, solve_pf_batch
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario

# ----- which point a snapshot's setpoints come from (extra["fallback"]) ------------------
FROM_SOLVER = "none"  # the formulation's own solution
FROM_COLD = "cold"  # IPOPT started cold after the warm start failed
FROM_SOCP = "socp"  # the SOCP relaxation's setpoints
FROM_NO_ACTION = "no-action"  # Q = 0

# ----- which solver proved the point optimal (extra["certified_by"]; "" = none) ---------
CERTIFIED_BY_SOCP = "socp"  # AC-feasible and within the relaxation's bound (the fast path)
CERTIFIED_BY_IPOPT = "ipopt"  # IPOPT converged to it


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


def evaluated_result(
    strategy: str,
    k: float,
    scenario: Scenario,
    problem: OpfProblem,
    data: SnapshotData,
    q_pu: np.ndarray,
    wall_ms: float,
    status: np.ndarray,
    lower_bound_kw: np.ndarray,
    extra: dict[str, np.ndarray],
    power_flows: np.ndarray | int = 0,
    pf: PowerFlowResult | None = None,
    p_pu: np.ndarray | None = None,
) -> StrategyResult:
    """A formulation's result: setpoints `q_pu` (S, n_der) — with the DER's active power
    `p_pu` (S, n_der) where the formulation curtails — evaluated by the batched AC power
    flow (or `pf`, that evaluation already done), with extra["ac_feasible"] (the point
    meets every limit, `OpfProblem.feasible`) and the scalar extra["slack_export"].

    `lower_bound_kw` (the relaxation's, per snapshot) bounds the losses of the points that
    meet the limits, so the result carries it only where its own point does; elsewhere
    (no feasible point found: infeasible, solver-failed, a point applied anyway under the
    paper's policy) the bound is NaN there and kept as extra["relaxation_bound_kw"]."""
    net = scenario.net
    q_mvar = np.asarray(q_pu, dtype=float).reshape(scenario.n_snapshots, len(net.ders)) * net.base_mva
    p_mw = None if p_pu is None else np.asarray(p_pu, dtype=float).reshape(q_mvar.shape) * net.base_mva
    if pf is None:
        pf = solve_pf_batch(net, scenario.injections(q_mvar, p_mw))
    feasible = problem.feasible(pf, data.s_fixed)
    full: dict[str, object] = {**extra, "ac_feasible": feasible, "slack_export": problem.slack_export}
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
        extra=full,
        p_mw=p_mw,
    )
