"""The AC OPF that may curtail (`acopf:curtail=true`): the DER's active power is a
decision too, within [min(P, 0), P] of the power P each has, its Q within the capability
at the power it delivers (`problem.PqCapability`), and the objective the losses plus the
power curtailed (kW) — so curtailment is bought only where it saves more losses than it
wastes, or where nothing else holds the limits.

Per snapshot, as the plain AC OPF (`acopf`, `policy`): the relaxation that curtails
(`relaxation.curtail_solves`, the bound) settles it where its point, AC-evaluated, meets the
limits and its cost is within CERTIFY_RTOL of the bound (certified by "socp"), or where it
is infeasible; else IPOPT (`models.polar_ac`, warm from the last answer; with
`fallback="chain"` cold on failure, then the relaxation's point if AC-feasible, then no
action — Q = 0 at P — if feasible; with "paper", no action after one failure). The
interval bounds' proofs (`infeasibility`) assume the DER's power fixed: they are not used.
"""

from __future__ import annotations

import numpy as np

from opfbench.capability import p_for_q, qmax
from opfbench.formulations.acopf_options import Fallback
from opfbench.formulations.evaluation import evaluated_result, solver_record
from opfbench.formulations.model import model_for
from opfbench.formulations.models.conic import SnapshotSolve as SocpSolve
from opfbench.formulations.models.polar_ac import AcOpf
from opfbench.formulations.policy import CERTIFY_RTOL
from opfbench.formulations.problem import CurtailData, OpfProblem, PqCapability, SnapshotData, curtail_data
from opfbench.formulations.solver_cache import per_thread
from opfbench.formulations.solvers.ipopt_adapter import IpoptSolve
from opfbench.formulations.solves import curtail_solves
from opfbench.powerflow import solve_pf_batch
from opfbench.result import (
    CERTIFIED_BY_IPOPT,
    CERTIFIED_BY_SOCP,
    FALLBACK_COLD,
    FALLBACK_NO_ACTION,
    FALLBACK_SOCP,
    FROM_COLD,
    FROM_NO_ACTION,
    FROM_SOCP,
    FROM_SOLVER,
    INFEASIBLE,
    OK,
    SOLVER_FAILED,
    StrategyResult,
)
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now


def _within(scenario: Scenario, q_pu: np.ndarray, p_pu: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    """A relaxation's (Q, P) (S, n_der) p.u. within the capability exactly: where its Q lies
    beyond the S̄ circle at its P by the solver's tolerance (near the circle's top a
    1e-7 error in P is a 1e-3 error in Q), P lowered to where it covers Q
    (`capability.p_for_q`), then Q clipped to the capability at that P."""
    net = scenario.net
    base, night = net.base_mva, scenario.night_q()
    p = p_for_q(net.der_kinds, q_pu * base, p_pu * base, net.der_rating_mw, net.der_s_mva, night, share)
    cap = share * qmax(net.der_kinds, np.maximum(p, 0.0), net.der_rating_mw, net.der_s_mva, night)
    return np.clip(q_pu * base, -cap, cap) / base, p / base


def _cost_kw(losses_kw: np.ndarray, p_pu: np.ndarray, data: CurtailData, base_mva: float) -> np.ndarray:
    """(S,) losses plus the power curtailed, kW."""
    return losses_kw + 1e3 * base_mva * (data.p_avail - p_pu).sum(axis=1)


class _Snapshot:
    """How one snapshot was settled: (Q, P) p.u., status, fallback, certifier, attempts."""

    def __init__(self, q: np.ndarray, p: np.ndarray, status: str, fallback: str, certified_by: str, socp: SocpSolve):
        self.q, self.p, self.status, self.fallback, self.certified_by, self.socp = q, p, status, fallback, certified_by, socp
        self.attempts: list[IpoptSolve] = []
        self.power_flows = 0

    def diagnostics(self) -> dict:
        socp = self.socp.diagnostics()
        by_socp = self.certified_by == CERTIFIED_BY_SOCP
        accepted = self.attempts[-1] if self.attempts and self.attempts[-1].success else None
        return {
            "solver_status": socp["solver_status"]
            if by_socp or not self.attempts
            else " → ".join(a.status for a in self.attempts),
            "iterations": sum(a.iterations for a in self.attempts),
            "solve_ms": socp["solve_ms"] if by_socp else sum(a.solve_ms for a in self.attempts),
            "warm_start": bool(self.attempts and self.attempts[0].warm),
            "objective_kw": self.socp.objective_kw if by_socp else accepted.objective_kw if accepted is not None else np.nan,
            "fallback": self.fallback,
            "certified_by": self.certified_by,
            "relaxation_gap": self.socp.relaxation_gap,
            "socp_status": socp["solver_status"],
            "socp_ms": socp["solve_ms"],
            "proven_infeasible": self.status == INFEASIBLE and not self.attempts,  # by the relaxation
        }


def run_curtailing(
    scenario: Scenario, k: float, *, slack_export: bool = True, fallback: Fallback = "chain", solver: str = "auto"
) -> StrategyResult:
    """The AC OPF that may curtail on every snapshot of `scenario` at reserve k (module
    docstring); `solver="ipopt"` runs IPOPT on every snapshot. The result carries the
    curtailed power; lower_bound_kw bounds losses + curtailed power."""
    if scenario.q_limit_mvar is not None:  # its capability is a function of the power it delivers (PqCapability)
        raise ValueError("the AC OPF that may curtail takes no fixed reactive limit (q_limit_mvar)")
    start = now()
    net = scenario.net
    base, n_der = net.base_mva, len(net.ders)
    data = curtail_data(scenario, k)
    cap = PqCapability.of(net, k)
    problem = OpfProblem.of(net, slack_export)
    solves = curtail_solves(net, data, k, slack_export)
    q0 = np.array([s.q_pu if s.q_pu is not None else np.zeros(n_der) for s in solves]).reshape(-1, n_der)
    p0 = np.array([s.p_pu if s.p_pu is not None else data.p_avail[i] for i, s in enumerate(solves)]).reshape(-1, n_der)
    q0, p0 = _within(scenario, q0, p0, cap.share)
    pf = solve_pf_batch(net, scenario.injections(q0 * base, p0 * base))
    bound = np.array([s.objective_kw for s in solves])
    optimal = np.array([s.optimal for s in solves], dtype=bool)
    with np.errstate(invalid="ignore"):
        close = np.abs(_cost_kw(pf.losses_kw, p0, data, base) - bound) <= CERTIFY_RTOL * np.abs(bound)
    certified = optimal & problem.feasible(pf, data.s_fixed) & close & (solver == "auto")
    exact = model_for("exact", net)
    opf = per_thread(net, (f"{exact.name}-curtail", bool(slack_export)), lambda: AcOpf(net, slack_export, curtail=True))
    last: IpoptSolve | None = None
    settled = []
    for i, socp in enumerate(solves):
        if certified[i]:
            settled.append(_Snapshot(q0[i], p0[i], OK, FROM_SOLVER, CERTIFIED_BY_SOCP, socp))
        elif socp.infeasible and solver == "auto":
            settled.append(_Snapshot(np.zeros(n_der), data.p_avail[i], INFEASIBLE, FROM_NO_ACTION, "", socp))
        else:
            snap = _ipopt(opf, data, cap, i, socp, last, fallback, problem, scenario)
            last = snap.attempts[-1] if snap.certified_by == CERTIFIED_BY_IPOPT else last
            settled.append(snap)
    q = np.array([s.q for s in settled]).reshape(-1, n_der)
    p = np.array([s.p for s in settled]).reshape(-1, n_der)
    record, extra = solver_record(exact, [s.diagnostics() for s in settled])
    return evaluated_result(
        "acopf",
        k,
        scenario,
        problem,
        SnapshotData(data.s_fixed, np.zeros_like(data.p_avail)),
        q,
        elapsed_ms(start),
        status=np.array([s.status for s in settled], dtype=object),
        lower_bound_kw=bound,
        solver=record,
        extra=extra,
        power_flows=np.array([s.power_flows + 1 for s in settled]),
        p_pu=p,
    )


def _ipopt(
    opf: AcOpf,
    data: CurtailData,
    cap: PqCapability,
    i: int,
    socp: SocpSolve,
    last: IpoptSolve | None,
    fallback: Fallback,
    problem: OpfProblem,
    scenario: Scenario,
) -> _Snapshot:
    """Snapshot i by IPOPT under the failure policy `fallback` (module docstring)."""
    n_der = len(problem.net.ders)
    attempts = [opf.solve_curtailing(data, i, cap, last)]
    if not attempts[-1].success and fallback == "chain" and last is not None:
        attempts.append(opf.solve_curtailing(data, i, cap, None))
    if attempts[-1].success:
        x = attempts[-1].q_pu
        cold = len(attempts) > 1
        snap = _Snapshot(
            x[:n_der], x[n_der:], FALLBACK_COLD if cold else OK, FROM_COLD if cold else FROM_SOLVER, CERTIFIED_BY_IPOPT, socp
        )
        snap.attempts = attempts
        return snap
    relaxed = []
    if fallback == "chain" and socp.q_pu is not None and socp.p_pu is not None:
        q, p = _within(scenario.take(np.array([i])), socp.q_pu[None], socp.p_pu[None], cap.share)
        relaxed = [(q[0], p[0], FALLBACK_SOCP, FROM_SOCP)]
    candidates = relaxed + [(np.zeros(n_der), data.p_avail[i], FALLBACK_NO_ACTION, FROM_NO_ACTION)]
    flows = 0
    for q, p, status, source in candidates:
        assert q is not None and p is not None
        flows += 1
        base = problem.net.base_mva
        pf = solve_pf_batch(problem.net, scenario.take(np.array([i])).injections(q[None] * base, p[None] * base))
        if problem.feasible(pf, data.s_fixed[i : i + 1])[0]:
            snap = _Snapshot(q, p, status, source, "", socp)
            break
    else:
        shown = any(a.infeasible for a in attempts) or socp.infeasible
        snap = _Snapshot(np.zeros(n_der), data.p_avail[i], INFEASIBLE if shown else SOLVER_FAILED, FROM_NO_ACTION, "", socp)
    snap.attempts, snap.power_flows = attempts, flows
    return snap
