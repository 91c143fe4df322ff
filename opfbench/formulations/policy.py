"""How the AC OPF settles each snapshot: the certified fast path, and IPOPT under a failure
policy (`options.FALLBACKS`), every decision recorded.

Fast path (`fast_path`): the SOCP relaxation's setpoints of every snapshot, evaluated by
ONE batched AC power flow. Where the relaxation is infeasible the AC OPF is too, and so
it is where the interval bounds on the exact branch flows prove it
(`infeasibility.proven_infeasible`, computed first: then the relaxation is not solved
there; a voltage limit out of reach, or the slack must export
where it may not; the solver_status says which — the relaxation cannot show these: it may
burn power in losses no AC point has); where its setpoints are AC-feasible
(`OpfProblem.feasible`) and their AC losses lie within CERTIFY_RTOL (relative) of the
relaxation's bound — a lower bound on every AC-feasible point's losses — they are the AC
optimum up to that tolerance (certified by "socp").

IPOPT's snapshots (`IpoptPolicy.settle`, warm-started from its last success):

- `chain`: warm IPOPT → cold IPOPT → the SOCP relaxation's setpoints if, AC evaluated,
  they are feasible → no action if feasible. Status "ok" / "fallback-cold" /
  "fallback-socp" / "fallback-no-action".
- `paper`: IPOPT once (warm when possible); on failure, no action — as the paper did.

When no point is found feasible, the setpoints are those of no action (fallback
"no-action", its AC losses reported) and the status is "infeasible" if IPOPT reported
infeasibility or the SOCP relaxation or the bounds prove it, "solver-failed"
otherwise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from opfbench.formulations.acopf_options import Fallback
from opfbench.formulations.model import ExactModel
from opfbench.formulations.models.conic import SnapshotSolve
from opfbench.formulations.problem import OpfProblem, SnapshotData
from opfbench.formulations.solvers.ipopt_adapter import IpoptSolve
from opfbench.powerflow import PowerFlowResult, solve_pf, solve_pf_batch
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
)
from opfbench.scenario import Scenario

CERTIFY_RTOL = 1e-6  # fast path: AC losses of the SOCP point ≤ bound·(1 + this) (relative)


@dataclass
class Settled:
    """How one snapshot was settled: its setpoints (p.u.), status, where the point comes
    from (`result.FROM_*`), the IPOPT attempts, the relaxation's solve, the power flows
    the policy used to check points, who certified it, its losses where certified by
    the SOCP (kW), and the bounds' proof of its infeasibility (`infeasibility`; "" if none)."""

    q_pu: np.ndarray
    status: str
    fallback: str
    attempts: list[IpoptSolve]
    socp: SnapshotSolve
    power_flows: int
    certified_by: str
    objective_kw: float = np.nan
    proof: str = ""

    @property
    def accepted(self) -> IpoptSolve | None:
        return self.attempts[-1] if self.attempts and self.attempts[-1].success else None

    def diagnostics(self) -> dict:
        """The snapshot's `extra` entries (see `acopf.run_acopf`)."""
        acc = self.accepted
        socp = self.socp.diagnostics()
        by_socp = self.certified_by == CERTIFIED_BY_SOCP
        if self.proof:
            solver_status = self.proof
        elif by_socp or not self.attempts:
            solver_status = socp["solver_status"]
        else:
            solver_status = " → ".join(a.status for a in self.attempts)
        return {
            "solver_status": solver_status,
            "iterations": sum(a.iterations for a in self.attempts),
            "solve_ms": socp["solve_ms"] if by_socp else sum(a.solve_ms for a in self.attempts),
            "warm_start": bool(self.attempts and self.attempts[0].warm),
            "objective_kw": self.objective_kw if by_socp else acc.objective_kw if acc else np.nan,
            "fallback": self.fallback,
            "certified_by": self.certified_by,
            "relaxation_gap": self.socp.relaxation_gap,
            "socp_status": socp["solver_status"],
            "socp_ms": socp["solve_ms"],
            "proven_infeasible": self.status == INFEASIBLE and not self.attempts,  # by the relaxation or the bounds
        }


@dataclass(frozen=True)
class FastPath:
    """The SOCP setpoints of every snapshot, AC-evaluated by one batched power flow, and
    the bounds' proof of infeasibility of each snapshot."""

    q_pu: np.ndarray  # (S, n_der); zeros where the relaxation was not solved
    pf: PowerFlowResult
    certified: np.ndarray  # (S,) bool
    proofs: np.ndarray  # (S,) str: `infeasibility.proven_infeasible`

    def settled(self, i: int, socp: SnapshotSolve) -> Settled | None:
        """Snapshot i settled without IPOPT — certified, or proven infeasible by the
        relaxation or the bounds (then no action) — else None."""
        if self.certified[i]:
            return Settled(self.q_pu[i], OK, FROM_SOLVER, [], socp, 0, CERTIFIED_BY_SOCP, float(self.pf.losses_kw[i]))
        if socp.infeasible or self.proofs[i]:
            proof = "" if socp.infeasible else self.proofs[i]
            return Settled(np.zeros_like(self.q_pu[i]), INFEASIBLE, FROM_NO_ACTION, [], socp, 1, "", proof=proof)
        return None


def fast_path(
    scenario: Scenario, problem: OpfProblem, data: SnapshotData, solves: tuple[SnapshotSolve, ...], proofs: np.ndarray
) -> FastPath:
    """The fast path's evaluation of every snapshot (module docstring); `proofs`: the
    snapshots' `infeasibility.proven_infeasible` (their relaxation need not be solved)."""
    net = scenario.net
    n_der = len(net.ders)
    optimal = np.array([s.optimal for s in solves], dtype=bool)
    q_pu = np.array([s.q_pu if s.q_pu is not None else np.zeros(n_der) for s in solves]).reshape(len(solves), n_der)
    pf = solve_pf_batch(net, scenario.injections(q_pu * net.base_mva))
    bound = np.array([s.objective_kw for s in solves])
    with np.errstate(invalid="ignore"):
        close = np.abs(pf.losses_kw - bound) <= CERTIFY_RTOL * np.abs(bound)
    return FastPath(q_pu, pf, optimal & problem.feasible(pf, data.s_fixed) & close, proofs)


def merge_flows(fast: PowerFlowResult, rest: PowerFlowResult, rows: np.ndarray) -> PowerFlowResult:
    """`fast` with the snapshots `rows` replaced by `rest`'s (in order)."""
    v, conv, it = fast.v.copy(), np.array(fast.converged, copy=True), np.array(fast.iterations, copy=True)
    v[rows], conv[rows], it[rows] = rest.v, rest.converged, rest.iterations
    return PowerFlowResult(fast.net, v, conv, it)


class IpoptPolicy:
    """Settles snapshots with IPOPT one by one under a failure policy, carrying the warm start."""

    def __init__(
        self,
        data: SnapshotData,
        problem: OpfProblem,
        fallback: Fallback,
        socp: tuple[SnapshotSolve, ...],
        exact: Callable[[], ExactModel],
    ):
        self.data, self.problem = data, problem
        self.fallback, self.socp = fallback, socp
        self.net = problem.net
        self.start: IpoptSolve | None = None
        self._exact = exact

    @property
    def opf(self) -> ExactModel:
        return self._exact()  # built on first use only

    def _feasible(self, i: int, q_pu: np.ndarray) -> bool:
        s_fixed = self.data.s_fixed[i]
        s_mw = (s_fixed + 1j * (self.problem.der_at_bus @ q_pu)) * self.net.base_mva
        return bool(self.problem.feasible(solve_pf(self.net, s_mw), s_fixed)[0])

    def settle(self, i: int) -> Settled:
        s_fixed, q_limit = self.data.s_fixed[i], self.data.q_limit[i]
        socp = self.socp[i]
        attempts = [self.opf.solve(s_fixed, q_limit, self.start)]
        if not attempts[-1].success and self.fallback == "chain" and self.start is not None:
            attempts.append(self.opf.solve(s_fixed, q_limit, None))
        if attempts[-1].success:
            self.start = attempts[-1]
            retried = len(attempts) > 1
            return Settled(
                attempts[-1].q_pu,
                FALLBACK_COLD if retried else OK,
                FROM_COLD if retried else FROM_SOLVER,
                attempts,
                socp,
                0,
                CERTIFIED_BY_IPOPT,
            )
        flows = 0
        if self.fallback == "chain" and socp.q_pu is not None:
            flows += 1
            if self._feasible(i, socp.q_pu):
                return Settled(socp.q_pu, FALLBACK_SOCP, FROM_SOCP, attempts, socp, flows, "")
        no_action = np.zeros_like(q_limit)
        flows += 1
        if self._feasible(i, no_action):
            return Settled(no_action, FALLBACK_NO_ACTION, FROM_NO_ACTION, attempts, socp, flows, "")
        shown = any(a.infeasible for a in attempts) or socp.infeasible
        return Settled(no_action, INFEASIBLE if shown else SOLVER_FAILED, FROM_NO_ACTION, attempts, socp, flows, "")
