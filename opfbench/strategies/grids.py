"""The grid a scenario's DER act on, as the local-rule engine sees it: the network answering
DER setpoints with one batched AC power flow, and what a DER measures at its own
connection — for a balanced network (bus level) and a three-phase feeder (node level)
alike, so one engine (`opfbench.strategies.rule_engine`) runs every rule on both.

- `BusGrid`: a balanced `Network`; a DER measures its bus's |V| and the flows on the
  lines at its bus (`meters.LocalMeters`).
- `PhaseGrid`: a three-phase `PhaseNetwork`; a DER measures its own phase voltage in p.u.
  of its base (phase to neutral, or phase to phase for a delta unit; a three-phase unit
  the average of its phases: `PhaseFlowResult.der_vm`), and the flows on its phases'
  conductors of the elements at its bus (`meters.PhaseMeters`). Setpoints are per DER; a
  three-phase unit splits its P and Q equally over its phases (the branches' shares).

`grid_of(scenario)` picks the one the scenario's network needs.
"""

from __future__ import annotations

import numpy as np

from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult, solve_pf_batch
from opfbench.powerflow.multiphase import PhaseFlowResult, solve_phase_flow
from opfbench.scenario import Scenario
from opfbench.strategies.meters import LocalMeters, PhaseMeters

Flow = PowerFlowResult | PhaseFlowResult


class BusGrid:
    """A balanced network (module docstring): bus injections of the DER at their buses."""

    def __init__(self, scenario: Scenario) -> None:
        net = scenario.net
        assert isinstance(net, Network)
        self.scenario, self.net = scenario, net
        self.meters: LocalMeters = LocalMeters.of(net)
        self.place = np.zeros((len(net.ders), net.n_bus))
        self.place[np.arange(len(net.ders)), net.der_bus] = 1.0  # DER → bus
        self.base = scenario.injections(np.zeros((scenario.n_snapshots, len(net.ders))))
        self.available = scenario.der_p_mw

    def answer(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, v0: np.ndarray | None) -> PowerFlowResult:
        if v0 is None and rows.size == self.scenario.n_snapshots and not q_mvar.any() and p_mw is None:
            return solve_pf_batch(self.net, self.base)  # the no-action state (shared: `memo.FlowMemo`)
        injections = self.base[rows] + 1j * (q_mvar @ self.place)
        if p_mw is not None:
            injections = injections + (p_mw - self.available[rows]) @ self.place
        return solve_pf_batch(self.net, injections, v0=v0)

    def view(self, v: np.ndarray) -> PowerFlowResult:
        return PowerFlowResult(self.net, v, np.ones(v.shape[0], dtype=bool), np.zeros(v.shape[0], dtype=np.int64))

    def der_vm(self, flow: Flow) -> np.ndarray:
        """(S', n_der) the |V| of each DER's bus, p.u."""
        return np.abs(flow.v[:, self.net.der_bus])

    def outflow(self, flow: Flow) -> np.ndarray:
        """(S', n_der, m) what each DER's meters read (`meters.LocalMeters.outflow`)."""
        assert isinstance(flow, PowerFlowResult)
        return self.meters.outflow(flow)

    def node_vm(self, v: np.ndarray) -> np.ndarray:
        return np.abs(v)

    def final(self, v: np.ndarray, converged: np.ndarray, flows: np.ndarray) -> PowerFlowResult:
        return PowerFlowResult(self.net, v, converged, flows)


class PhaseGrid:
    """A three-phase feeder (module docstring): every load element at its own P and Q, the
    DER as constant-power branches. Keeps each snapshot's last answer's losses and
    mismatch for `final`."""

    def __init__(self, scenario: Scenario) -> None:
        net = scenario.net
        assert isinstance(net, PhaseNetwork)
        self.scenario, self.net = scenario, net
        self.meters: PhaseMeters = PhaseMeters.of(net)
        self.load_p, self.load_q = scenario.element_loads()
        self.available = scenario.der_p_mw
        n = scenario.n_snapshots
        self.losses_kw = np.full(n, np.nan)
        self.mismatch = np.full(n, np.inf)

    def answer(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, v0: np.ndarray | None) -> PhaseFlowResult:
        p = self.available[rows] if p_mw is None else p_mw
        flow = solve_phase_flow(self.net, self.load_p[rows], self.load_q[rows], p, q_mvar, v0=v0)
        self.losses_kw[rows] = flow.losses_kw
        self.mismatch[rows] = flow.mismatch
        return flow

    def view(self, v: np.ndarray) -> PhaseFlowResult:
        n = v.shape[0]
        return PhaseFlowResult(self.net, v, np.ones(n, dtype=bool), np.zeros(n, dtype=np.int64), np.zeros(n), np.full(n, np.nan))

    def der_vm(self, flow: Flow) -> np.ndarray:
        """(S', n_der) each DER's own phase voltage, p.u. (`PhaseFlowResult.der_vm`)."""
        assert isinstance(flow, PhaseFlowResult)
        return flow.der_vm

    def outflow(self, flow: Flow) -> np.ndarray:
        """(S', n_der, m) what each DER's per-phase meters read (`meters.PhaseMeters.outflow`)."""
        assert isinstance(flow, PhaseFlowResult)
        return self.meters.outflow(flow)

    def node_vm(self, v: np.ndarray) -> np.ndarray:
        return np.abs(v) / self.net.node_base_v

    def final(self, v: np.ndarray, converged: np.ndarray, flows: np.ndarray) -> PhaseFlowResult:
        return PhaseFlowResult(self.net, v, converged, flows, self.mismatch.copy(), self.losses_kw.copy())


RuleGrid = BusGrid | PhaseGrid
"""What the rule engine asks of a grid: `answer(rows, q, p, v0)` the flow of some
snapshots at DER setpoints (P None: P^C; v0 a warm start), `view(v)` converged voltages
as a flow to measure, `der_vm(flow)` each DER's measured voltage, `outflow(flow)` its
meters, `node_vm(v)` every bus's or node's |V| (the settling check), `final(v, converged,
flows)` every snapshot's last answer as one flow (the result's figures)."""


def grid_of(scenario: Scenario) -> RuleGrid:
    """The grid of the scenario's network (module docstring)."""
    return PhaseGrid(scenario) if isinstance(scenario.net, PhaseNetwork) else BusGrid(scenario)
