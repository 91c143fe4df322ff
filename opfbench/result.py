"""The result record every strategy returns — local rules and OPF formulations alike —
so the benchmark treats them the same. Arrays carry a leading snapshot axis S.

Units: Q in MVAr (positive = injected), losses in kW, voltages in p.u., times in ms.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from opfbench.jsonio import json_safe
from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult
from opfbench.powerflow.multiphase import PhaseFlowResult

if TYPE_CHECKING:
    from opfbench.scenario import Scenario

# ----- status vocabulary (StrategyResult.status), the one list every table and report uses --
OK = "ok"  # the strategy's own point, AC-evaluated (formulations: an optimum)
FALLBACK_COLD = "fallback-cold"  # warm IPOPT failed, cold IPOPT from a flat start solved it
FALLBACK_SOCP = "fallback-socp"  # IPOPT failed; the SOCP's setpoints, AC-evaluated, are feasible
FALLBACK_NO_ACTION = "fallback-no-action"  # nothing better found; Q = 0 is AC-feasible
INFEASIBLE = "infeasible"  # the OPF has no feasible point (shown by a solver); Q = 0 reported
SOLVER_FAILED = "solver-failed"  # solver failed, no feasible fallback, infeasibility not shown
PF_DIVERGED = "pf-diverged"  # the AC power flow at the setpoints did not converge: no figures
NOT_SETTLED = "not-settled"  # a closed-loop local rule did not settle within its iteration limit: its last iterate
RULE_NON_FINITE = "rule-non-finite"  # a local rule gave NaN or inf for some DER: no setpoint, no figures
STATUSES = (
    OK,
    FALLBACK_COLD,
    FALLBACK_SOCP,
    FALLBACK_NO_ACTION,
    INFEASIBLE,
    SOLVER_FAILED,
    PF_DIVERGED,
    NOT_SETTLED,
    RULE_NON_FINITE,
)


MAX_VUF = "max_vuf_pct"  # a three-phase feeder's worst voltage unbalance factor |V₂|/|V₁| per snapshot, %
VM_ERROR = "vm_error_pu"  # an approximation's largest |predicted − power flow| monitored voltage per snapshot, p.u.

# ----- where a formulation's setpoints come from (SolverRecord.fallback) --------------------
FROM_SOLVER = "none"  # the model's own solution
FROM_COLD = "cold"  # IPOPT started cold after the warm start failed
FROM_SOCP = "socp"  # the relaxation's setpoints
FROM_NO_ACTION = "no-action"  # Q = 0
# ----- which solver proved the point the AC optimum (SolverRecord.certified_by; "" = none) ----
CERTIFIED_BY_SOCP = "socp"  # AC-feasible and within the relaxation's bound (the fast path)
CERTIFIED_BY_IPOPT = "ipopt"  # IPOPT converged to it
CERTIFIED_BY_SDP = "sdp3"  # a three-phase optimum within the SDP relaxation's bound (`formulations.three_phase`)
CERTIFIED_BY_UNIQUE = "unique"  # no decision, and the power flow's point proven the only one (`formulations.unique_point`)


@dataclass(frozen=True, eq=False)
class SolverRecord:
    """What a formulation's solvers did at each of S snapshots — the typed diagnostics the
    study's tables and the report read (a local rule's result has none).

    model: the formulation model that answered (`formulations.model`); meaning: what its
    objective is for the benchmark ("optimum", "bound" or "estimate"); objective_kw (S,)
    the model's own objective where it gave one (NaN elsewhere; kW); solver_status (S,)
    the solver's return status (attempts joined by " → "; the proof's reason where bounds
    proved infeasibility); fallback (S,) where the setpoints come from (`FROM_*`);
    certified_by (S,) who proved the point the AC optimum (`CERTIFIED_BY_*`, "" none);
    solve_ms (S,) the answering solver's time, ms; iterations (S,) its iterations."""

    model: str
    meaning: str
    objective_kw: np.ndarray
    solver_status: np.ndarray
    fallback: np.ndarray
    certified_by: np.ndarray
    solve_ms: np.ndarray
    iterations: np.ndarray

    def take(self, rows: np.ndarray) -> "SolverRecord":
        """The record of the snapshots `rows`."""
        return SolverRecord(
            self.model,
            self.meaning,
            self.objective_kw[rows],
            self.solver_status[rows],
            self.fallback[rows],
            self.certified_by[rows],
            self.solve_ms[rows],
            self.iterations[rows],
        )

    def snapshot(self, i: int) -> dict:
        """Snapshot i as `StrategyResult.snapshot_json` lists it."""
        return {
            "model": self.model,
            "objective": self.meaning,
            "objective_kw": self.objective_kw[i],
            "solver_status": str(self.solver_status[i]),
            "fallback": str(self.fallback[i]),
            "certified_by": str(self.certified_by[i]),
            "solve_ms": self.solve_ms[i],
            "iterations": int(self.iterations[i]),
        }


@dataclass(frozen=True)
class Reference:
    """Each step's frontier point at a configuration's own compliance (the optimum with the
    voltage band widened just enough to cover the step's excursion,
    `formulations.frontier.reference`), (S,) each: the optimum's cost (kW), its bound
    (kW), that widening ε (p.u.), whether it is the optimum's that may curtail, and what
    its DER may use (`formulations.frontier.RESERVE`, `FORECAST`, `CAPABILITY`; "" where no
    frontier bounds the step: setpoints beyond the capability)."""

    cost_kw: np.ndarray
    bound_kw: np.ndarray
    eps_pu: np.ndarray
    curtails: np.ndarray
    limit: np.ndarray


@dataclass(eq=False)
class StrategyResult:
    """Outcome of one strategy over S snapshots.

    q_mvar (S, n_der) setpoints; losses_kw (S,) from the AC power flow at those setpoints
    and vm (S, n_bus) its |V| p.u. — both NaN where the flow did not converge (status
    "pf-diverged": a diverged iterate is no operating point, so it gives no figure);
    status (S,) strings;
    power_flows (S,) power flows used per snapshot; wall_ms total wall time for the batch;
    excursion_mvar (S,) the largest amount by which any setpoint exceeds its DER's physical
    capability at the current P (Algorithm 3 without `safe` can do that); lower_bound_kw
    (S,) a certified lower bound on the losses of any point meeting the strategy's limits,
    given where the strategy provides one and its own point meets them (so losses_kw ≥
    lower_bound_kw up to solver tolerance), NaN otherwise; solver: a formulation's typed
    diagnostics (`SolverRecord`; None for a local rule); extra: per-strategy diagnostics
    (arrays of length S or scalars).
    """

    strategy: str
    k: float
    net: Network | PhaseNetwork
    q_mvar: np.ndarray
    losses_kw: np.ndarray
    vm: np.ndarray
    status: np.ndarray
    power_flows: np.ndarray
    wall_ms: float
    excursion_mvar: np.ndarray
    lower_bound_kw: np.ndarray | None = None
    solver: SolverRecord | None = None
    extra: dict = field(default_factory=dict)
    curtailed_mw: np.ndarray | None = None

    @classmethod
    def from_setpoints(
        cls,
        strategy: str,
        k: float,
        scenario: "Scenario",
        q_mvar: np.ndarray,
        wall_ms: float,
        power_flows: np.ndarray | int = 0,
        pf: PowerFlowResult | PhaseFlowResult | None = None,
        status: np.ndarray | None = None,
        p_mw: np.ndarray | None = None,
        **kw,
    ) -> "StrategyResult":
        """Evaluate setpoints q_mvar (S, n_der), with the DER delivering `p_mw` (S, n_der) MW
        (None: their available power P^C), with the batched AC power flow (unless `pf`
        already holds that evaluation) and build the record. `power_flows` counts the
        flows the strategy itself used; the evaluation adds one per snapshot when run here.
        Snapshots whose flow did not converge get status "pf-diverged", NaN losses and NaN
        voltages."""
        q = np.atleast_2d(np.asarray(q_mvar, dtype=float))
        flows = np.broadcast_to(np.asarray(power_flows, dtype=np.int64), (q.shape[0],)).copy()
        if pf is None:
            pf = scenario.flow(q, p_mw)
            flows += 1
        conv = np.asarray(pf.converged, dtype=bool).reshape(-1)
        st = np.full(q.shape[0], OK, dtype=object) if status is None else np.asarray(status, dtype=object).copy()
        st[~conv] = PF_DIVERGED
        losses = np.where(conv, np.atleast_1d(pf.losses_kw), np.nan)
        vm = np.where(conv[:, None], np.atleast_2d(pf.vm), np.nan)
        physical = scenario.qmax_mvar(p_mw)
        excursion = np.maximum(np.abs(q) - physical, 0.0).max(axis=1, initial=0.0)
        curtailed = None if p_mw is None else np.maximum(scenario.der_p_mw - p_mw, 0.0)
        if isinstance(pf, PhaseFlowResult):  # what unbalance adds: the worst VUF of the snapshot, %
            vuf = 100.0 * np.max(pf.vuf, axis=1, initial=0.0)
            kw["extra"] = {MAX_VUF: np.where(conv, vuf, np.nan)} | kw.get("extra", {})
        return cls(
            strategy, float(k), scenario.net, q, losses, vm, st, flows, float(wall_ms), excursion, curtailed_mw=curtailed, **kw
        )

    @property
    def n_snapshots(self) -> int:
        return self.q_mvar.shape[0]

    def take(self, rows: np.ndarray, wall_ms: float) -> "StrategyResult":
        """The result of the snapshots `rows` (the solver record's and the extra arrays of
        length S taken likewise, the other extra values kept), with wall time `wall_ms`."""
        n = self.n_snapshots

        def part(value: object) -> object:
            return value[rows] if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == n else value

        lower = None if self.lower_bound_kw is None else self.lower_bound_kw[rows]
        return StrategyResult(
            self.strategy,
            self.k,
            self.net,
            self.q_mvar[rows],
            self.losses_kw[rows],
            self.vm[rows],
            self.status[rows],
            self.power_flows[rows],
            float(wall_ms),
            self.excursion_mvar[rows],
            lower,
            None if self.solver is None else self.solver.take(rows),
            {key: part(value) for key, value in self.extra.items()},
            None if self.curtailed_mw is None else self.curtailed_mw[rows],
        )

    @property
    def curtailed_kw(self) -> np.ndarray:
        """(S,) active power curtailed over all DER, kW (0 where none; NaN where the strategy
        gave no setpoint)."""
        total = np.zeros(self.n_snapshots) if self.curtailed_mw is None else 1e3 * self.curtailed_mw.sum(axis=1)
        return np.where(np.isnan(self.q_mvar).any(axis=1), np.nan, total)

    @property
    def vmin(self) -> np.ndarray:
        return self.vm.min(axis=1)

    @property
    def vmax(self) -> np.ndarray:
        return self.vm.max(axis=1)

    def voltage_violation(self) -> np.ndarray:
        """(S,) largest violation of the case's voltage limits (p.u., 0 when compliant, NaN
        where the flow did not converge)."""
        low = np.maximum(self.net.vmin - self.vm, 0.0)
        high = np.maximum(self.vm - self.net.vmax, 0.0)
        return np.maximum(low, high).max(axis=1)

    def snapshot_json(self, i: int = 0) -> dict:
        """The JSON contract of one snapshot (keys stable; units MVAr, kW, p.u., ms); a
        value that is not finite (no converged flow, no bound) is null. `q_mvar` is keyed by
        DER name (`Network.der_names`: unique, also where several DER share a bus),
        `der_bus` gives each DER's bus number."""
        names = self.net.der_names
        bus_ids = self.net.bus_ids[self.net.der_bus]
        out = {
            "strategy": self.strategy,
            "k": float(self.k),
            "status": str(self.status[i]),
            "losses_kw": self.losses_kw[i],
            "q_mvar": dict(zip(names, self.q_mvar[i], strict=True)),
            "der_bus": {name: b if isinstance(b, str) else int(b) for name, b in zip(names, bus_ids, strict=True)},
            "vmin": self.vmin[i],
            "vmax": self.vmax[i],
            "power_flows": int(self.power_flows[i]),
            "excursion_mvar": self.excursion_mvar[i],
            "curtailed_kw": self.curtailed_kw[i],
            "wall_ms": float(self.wall_ms),
        }
        if self.lower_bound_kw is not None:
            out["lower_bound_kw"] = self.lower_bound_kw[i]
        if self.solver is not None:
            out |= self.solver.snapshot(i)
        for key, value in self.extra.items():
            out[key] = value[i] if isinstance(value, np.ndarray) and value.ndim else value
        return json_safe(out)  # type: ignore[return-value]
