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
from opfbench.powerflow.multiphase import (
    PhaseFlowResult,
    PhaseIterate,
    branch_loads,
    certify,
    iterate_phase_flow,
    solve_phase_flow,
    voltages_within,
)
from opfbench.scenario import Scenario
from opfbench.strategies.meters import LocalMeters, PhaseMeters

Flow = PowerFlowResult | PhaseFlowResult
Step = Flow | PhaseIterate
"""A closed-loop step: a flow, or a three-phase iterate before its certificate."""


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
            return solve_pf_batch(self.net, self.base)  # the no-action state (remembered: `memo.FlowMemo`)
        injections = self.base[rows] + 1j * (q_mvar @ self.place)
        if p_mw is not None:
            injections = injections + (p_mw - self.available[rows]) @ self.place
        return solve_pf_batch(self.net, injections, v0=v0)

    def step(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, state: np.ndarray | None) -> PowerFlowResult:
        return self.answer(rows, q_mvar, p_mw, state)

    def state(self, flow: Step) -> np.ndarray:
        """(S', n_bus) the flow's bus voltages."""
        return flow.v

    def stepped(self, flow: Step) -> np.ndarray:
        assert isinstance(flow, PowerFlowResult)
        return np.asarray(flow.converged, dtype=bool)

    def view(self, v: np.ndarray) -> PowerFlowResult:
        return PowerFlowResult(self.net, v, np.ones(v.shape[0], dtype=bool), np.zeros(v.shape[0], dtype=np.int64))

    def der_vm(self, flow: Step) -> np.ndarray:
        """(S', n_der) the |V| of each DER's bus, p.u."""
        return np.abs(flow.v[:, self.net.der_bus])

    def outflow(self, flow: Step) -> np.ndarray:
        """(S', n_der, m) what each DER's meters read (`meters.LocalMeters.outflow`)."""
        assert isinstance(flow, PowerFlowResult)
        return self.meters.outflow(flow)

    def voltages_within(self, state: np.ndarray, before: np.ndarray, tol: float) -> np.ndarray:
        """(S',) no bus's |V| moved by more than `tol` p.u. from `before` to `state`."""
        return np.abs(np.abs(state) - np.abs(before)).max(axis=1, initial=0.0) <= tol

    def final(self, v: np.ndarray, converged: np.ndarray, flows: np.ndarray) -> PowerFlowResult:
        return PowerFlowResult(self.net, v, converged, flows)


class PhaseGrid:
    """A three-phase feeder (module docstring): every load element at its own P and Q, the
    DER as constant-power branches. The closed loop's steps are iterates
    (`powerflow.multiphase.PhaseIterate`: the currents at the nodes loads and DER touch,
    every node's voltage formed only where asked); `final` certifies each snapshot's last
    one at the setpoints it was solved for (kept per snapshot by `step`)."""

    def __init__(self, scenario: Scenario) -> None:
        net = scenario.net
        assert isinstance(net, PhaseNetwork)
        self.scenario, self.net = scenario, net
        self.meters: PhaseMeters = PhaseMeters.of(net)
        self.load_p, self.load_q = scenario.element_loads()
        self.loads = branch_loads(net, self.load_p, self.load_q)  # spread once for every step
        self.available = scenario.der_p_mw
        self.der_p = np.array(self.available, dtype=float)
        self.der_q = np.zeros_like(self.der_p)

    def answer(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, v0: np.ndarray | None) -> PhaseFlowResult:
        p = self.available[rows] if p_mw is None else p_mw
        return solve_phase_flow(self.net, self.load_p[rows], self.load_q[rows], p, q_mvar, v0=v0)

    def step(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, state: np.ndarray | None) -> Step:
        p = self.available[rows] if p_mw is None else p_mw
        self.der_p[rows], self.der_q[rows] = p, q_mvar
        start = None if state is None else self._resumed(state)
        return iterate_phase_flow(self.net, self.loads.columns(rows), p, q_mvar, start=start)

    def state(self, flow: Step) -> np.ndarray:
        """(S', r') what the loop keeps of the iterate (`PhaseIterate.kept`: what its node
        voltages follow from, with its voltages at the nodes K)."""
        assert isinstance(flow, PhaseIterate)
        return flow.kept

    def _resumed(self, state: np.ndarray, settled: np.ndarray | None = None, flows: np.ndarray | None = None) -> PhaseIterate:
        n = state.shape[0]
        settled = np.ones(n, dtype=bool) if settled is None else settled
        return PhaseIterate.resumed(self.net, state, settled, np.zeros(n, dtype=np.int64) if flows is None else flows)

    def stepped(self, flow: Step) -> np.ndarray:
        """(S',) the iteration converged (the mismatch is certified by `final`)."""
        assert isinstance(flow, PhaseIterate)
        return np.asarray(flow.settled, dtype=bool)

    def view(self, state: np.ndarray) -> Step:
        return self._resumed(state)

    def der_vm(self, flow: Step) -> np.ndarray:
        """(S', n_der) each DER's own phase voltage, p.u. (`PhaseFlowResult.der_vm`)."""
        assert isinstance(flow, PhaseFlowResult | PhaseIterate)
        return flow.der_vm

    def outflow(self, flow: Step) -> np.ndarray:
        """(S', n_der, m) what each DER's per-phase meters read (`meters.PhaseMeters.outflow`)."""
        assert isinstance(flow, PhaseFlowResult | PhaseIterate)
        return self.meters.outflow(flow)

    def voltages_within(self, state: np.ndarray, before: np.ndarray, tol: float) -> np.ndarray:
        """(S',) no node's |V| moved by more than `tol` p.u. of its base from `before` to
        `state` (`powerflow.multiphase.voltages_within`)."""
        return voltages_within(self._resumed(state), self._resumed(before), tol)

    def final(self, state: np.ndarray, converged: np.ndarray, flows: np.ndarray) -> PhaseFlowResult:
        return certify(self._resumed(state, converged, flows), self.loads, self.der_p, self.der_q)


class CertifiedPhaseGrid(PhaseGrid):
    """A three-phase feeder whose every closed-loop step is a certified power flow on every
    node (the state: every node's voltage; the settling check exact on every node): for
    feeders whose regulators move their taps inside the power flow (`?taps=control`), where
    each snapshot's taps follow its own voltages and no one factorization serves them all."""

    def __init__(self, scenario: Scenario) -> None:
        super().__init__(scenario)
        self.losses_kw = np.full(scenario.n_snapshots, np.nan)
        self.mismatch = np.full(scenario.n_snapshots, np.inf)

    def step(self, rows: np.ndarray, q_mvar: np.ndarray, p_mw: np.ndarray | None, state: np.ndarray | None) -> PhaseFlowResult:
        flow = self.answer(rows, q_mvar, p_mw, state)
        self.losses_kw[rows], self.mismatch[rows] = flow.losses_kw, flow.mismatch
        return flow

    def state(self, flow: Step) -> np.ndarray:
        assert isinstance(flow, PhaseFlowResult)
        return flow.v

    def stepped(self, flow: Step) -> np.ndarray:
        assert isinstance(flow, PhaseFlowResult)
        return np.asarray(flow.converged, dtype=bool)

    def view(self, state: np.ndarray) -> Step:
        n = state.shape[0]
        return PhaseFlowResult(
            self.net, state, np.ones(n, dtype=bool), np.zeros(n, dtype=np.int64), np.zeros(n), np.full(n, np.nan)
        )

    def voltages_within(self, state: np.ndarray, before: np.ndarray, tol: float) -> np.ndarray:
        base = self.net.node_base_v
        return np.abs(np.abs(state) / base - np.abs(before) / base).max(axis=1, initial=0.0) <= tol

    def final(self, state: np.ndarray, converged: np.ndarray, flows: np.ndarray) -> PhaseFlowResult:
        return PhaseFlowResult(self.net, state, converged, flows, self.mismatch.copy(), self.losses_kw.copy())


RuleGrid = BusGrid | PhaseGrid
"""What the rule engine asks of a grid: `answer(rows, q, p, v0)` the certified flow of some
snapshots at DER setpoints (P None: P^C; v0 a warm start); for the closed loop
`step(rows, q, p, state)` the same flow as the loop iterates it (warm started from
`state`), `state(flow)` what the loop keeps of it per snapshot, `stepped(flow)` whether its
iteration converged, `view(state)` kept states as a flow to measure,
`voltages_within(state, before, tol)` whether no bus's or node's |V| moved by more than
tol between two states (the settling check), `final(state, converged, flows)` every snapshot's last step as one certified flow
(the result's figures); `der_vm(flow)` each DER's measured voltage, `outflow(flow)` its
meters."""


def grid_of(scenario: Scenario) -> RuleGrid:
    """The grid of the scenario's network (module docstring)."""
    net = scenario.net
    if not isinstance(net, PhaseNetwork):
        return BusGrid(scenario)
    return CertifiedPhaseGrid(scenario) if net.tap_control and net.regulators else PhaseGrid(scenario)
