"""Test oracle: the AC OPF is never beaten by a feasible point.

On a snapshot where the OPF reached an optimum (status "ok" or "fallback-cold"), any other
strategy's setpoints that meet every limit of the OPF (AC-evaluated, `problem.ac_feasible`)
must have losses ≥ the OPF's. On radial feeders the relaxation is exact, so the OPF is
the global optimum and a violation is a bug; on meshed ones IPOPT's point is a local
optimum and a violation would show it. Snapshots where the other point is infeasible
prove nothing and are counted apart, as are feasible snapshots the OPF did not solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.errors import InputError
from opfbench.formulations.problem import ac_feasible, snapshot_data
from opfbench.powerflow import solve_pf_batch
from opfbench.result import FALLBACK_COLD, OK, StrategyResult
from opfbench.scenario import Scenario

TOLERANCE_KW = 1e-3


@dataclass(frozen=True)
class DominanceReport:
    """compared: snapshots with an OPF optimum and a feasible other point; other_infeasible:
    snapshots where the other point violates a limit (or its power flow diverged);
    opf_unsolved: feasible other point but no OPF optimum; violations: (snapshot, OPF kW,
    other kW) where the OPF lost by more than the tolerance."""

    compared: int
    other_infeasible: int
    opf_unsolved: int
    violations: tuple[tuple[int, float, float], ...]

    @property
    def ok(self) -> bool:
        return not self.violations


def opf_dominance(
    opf: StrategyResult, other: StrategyResult, scenario: Scenario, tol_kw: float = TOLERANCE_KW
) -> DominanceReport:
    """Check AC OPF losses ≤ `other`'s losses wherever `other` is feasible (see module doc).

    `opf` is a `run_acopf` result and `other` any strategy's result, both on `scenario`
    (same snapshots, same k for the OPF's limits). Feasibility of `other` is judged by the
    OPF's own limits, including its slack-export option."""
    if opf.strategy != "acopf":
        raise InputError(f"the first result must come from acopf, got {opf.strategy!r}")
    if other.net is not scenario.net or opf.net is not scenario.net:
        raise InputError("both results must be computed on the scenario's network")
    if not opf.n_snapshots == other.n_snapshots == scenario.n_snapshots:
        raise InputError(
            f"snapshot counts differ: acopf {opf.n_snapshots}, {other.strategy} "
            f"{other.n_snapshots}, scenario {scenario.n_snapshots}"
        )
    data = snapshot_data(scenario, opf.k)
    pf = solve_pf_batch(scenario.net, scenario.injections(other.q_mvar))
    feasible = ac_feasible(scenario.net, pf, data.s_fixed, bool(opf.extra["slack_export"]))
    solved = np.isin(opf.status, (OK, FALLBACK_COLD))
    compare = feasible & solved
    lost = compare & (opf.losses_kw > pf.losses_kw + tol_kw)
    violations = tuple((int(i), float(opf.losses_kw[i]), float(pf.losses_kw[i])) for i in np.flatnonzero(lost))
    return DominanceReport(int(compare.sum()), int((~feasible).sum()), int((feasible & ~solved).sum()), violations)
