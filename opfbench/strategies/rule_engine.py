"""The one engine of local rules: each DER measures at its own bus, sets its Q, and the grid
answers (a batched AC power flow over all S snapshots at once).

A local rule is a function `target(m, **options) -> (S, n_der)` of the `Measurements`
`m` — own-bus |V|, own active power P^C and forecast P^F, own-bus load P and Q, the power
on its incident lines (LFMA's meters) — giving each DER's Q target in MVAr, positive =
injected. Every target passes through the same limits as LLMA's and LFMA's:
Q = clip(target, ±L), L = (1 − k)·Qmax with the DER's capability (PV, DFIG or generic
inverter, "Q at night" where the night mode gives it) and Algorithm 3's forecast-aware
limit when the scenario carries a forecast (`opfbench.strategies.limits`).

Open loop: a rule that reads neither |V| nor line flows — quantities its own Q changes —
is evaluated once, and one power flow gives its operating point.

Closed loop: a rule that reads |V| or flows is solved for its steady state, the
quasi-static point an inverter settles to within a time step (the standards' response
times of 1–10 s ≪ 1-min steps), by a damped fixed-point iteration over batched power
flows, as OpenDSS's InvControl does it (`Change_deltaQ_factor`):

    Q_{n+1} = Q_n + α_n·(clip(target(m(Q_n)), ±L) − Q_n),

starting from the no-action state Q_0 = 0 with α = 0.5 per DER, adapted from the ratio of
the DER bus's successive voltage changes |ΔV_n| / |ΔV_{n−1}|: above 0.8 α falls by 0.1,
above 0.6 by 0.05 (while α > 0.2); below 0.2 it rises by 0.1, below 0.4 by 0.05 (while
α < 0.9). A snapshot has settled when the largest change the rule still asks for,
max|clip(target) − Q_n|, is ≤ `tol_q_mvar` and the largest bus-voltage change of the last
step is ≤ `tol_v_pu`; it then stops iterating (only the unsettled ones are solved again).
One that has not settled after `max_steps` steps keeps its last iterate — a converged
operating point, so it has figures — with status "not-settled" and its residual recorded.

Active power: a rule that caps it (Volt-Watt: `rules.Targets`) or runs with reactive
priority (`priority="q"`) moves each DER's P as well as its Q (`limits.Capability`): the
iteration settles both together, P_{n+1} = P_n + α_n·(P_wanted − P_n) with the same
factors, from P_0 = P^C; the residual and `tol_q_mvar` then bound the change still asked
of either (MVAr or MW), and the result carries the curtailed power.

On a three-phase feeder a step is the power flow's iterate (`grids.PhaseGrid`): only the
nodes loads and DER touch are solved, every node's voltage is formed only where the
settling check needs it, and each snapshot's last step — the one its figures come from —
is certified by its mismatch; a step whose iteration does not converge stops the snapshot
as a diverged flow does.

Statuses beyond "ok": "pf-diverged" (a flow did not converge: no figures), "not-settled",
"rule-non-finite" (the rule gave NaN or inf for some DER: no setpoint, no figures).
`StrategyResult.power_flows` counts every flow a snapshot needed, including the one that
evaluates the final setpoints; extra `residual_mvar` (S,): the last max|clip(target) − Q|.

Several DER at one bus each measure their share of its load (`Network.der_share`, in
proportion to S̄); the bus's line meters they read alike (`Measurements.bus_share`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.capability import check_reserve
from opfbench.result import NOT_SETTLED, OK, RULE_NON_FINITE, StrategyResult
from opfbench.scenario import Scenario
from opfbench.strategies.grids import Flow, RuleGrid, Step, grid_of
from opfbench.strategies.limits import Capability
from opfbench.strategies.rules import DEFAULT_SETTLING, RESIDUAL, Measurements, Rule, Settling, Targets, targets
from opfbench.threads import one_blas_thread
from opfbench.timing import elapsed_ms, now


@dataclass(frozen=True, eq=False)
class _Plant:
    """What the rows of one scenario give every rule without a power flow."""

    scenario: Scenario
    grid: RuleGrid
    s_rated: np.ndarray
    p_rated: np.ndarray
    kinds: np.ndarray
    fixed: dict[str, np.ndarray]  # "p_mw", "p_forecast_mw", "load_p_mw", "load_q_mvar", each (S, n_der)

    @classmethod
    def of(cls, scenario: Scenario, reads: frozenset[str]) -> "_Plant":
        net = scenario.net
        fixed = {}
        if "p" in reads:
            fixed["p_mw"] = scenario.der_p_mw
        if "p_forecast" in reads:
            pf = scenario.der_p_forecast_mw
            fixed["p_forecast_mw"] = scenario.der_p_mw if pf is None else pf
        if "load" in reads:
            fixed["load_p_mw"] = scenario.load_p_at_der_mw()
            fixed["load_q_mvar"] = scenario.load_q_at_der_mvar()
        return cls(scenario, grid_of(scenario), net.der_s_mva, net.der_rating_mw, np.asarray(net.der_kinds, dtype=str), fixed)

    def measure(self, reads: frozenset[str], rows: np.ndarray, pf: Step | None) -> Measurements:
        """The measurements of `rows`; `pf` the flow of exactly those rows (closed loop)."""
        every = rows.size == self.scenario.n_snapshots  # all rows in order: no copies
        values = {key: arr if every else arr[rows] for key, arr in self.fixed.items()}
        if pf is not None and "v" in reads:
            values["v_pu"] = self.grid.der_vm(pf)
        if pf is not None and "flows" in reads:
            values["line_mva"] = self.grid.outflow(pf)
        net = self.scenario.net
        return Measurements(
            reads, values, rows.size, self.s_rated, self.p_rated, self.kinds, self.grid.meters.valid, net.der_share
        )


class Grid:
    """The network answering setpoints on every snapshot (measure → set → the grid
    answers): each `answer` is one batched power flow, warm-started from the previous
    answer. `flows` keeps every answer; `diverged` (S,) the first answer whose flow did not
    converge (1, 2, …), 0 while none did."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.grid = grid_of(scenario)
        self.meters = self.grid.meters
        self.flows: list[Flow] = []
        self.diverged = np.zeros(scenario.n_snapshots, dtype=np.int64)

    def answer(self, q_mvar: np.ndarray) -> Flow:
        """The grid's answer to setpoints q_mvar (S, n_der)."""
        rows = np.arange(self.scenario.n_snapshots)
        pf = self.grid.answer(rows, q_mvar, None, self.flows[-1].v if self.flows else None)
        self.flows.append(pf)
        self.diverged[(self.diverged == 0) & ~np.asarray(pf.converged)] = len(self.flows)
        return pf


def run_rule(
    label: str,
    rule: Rule,
    scenario: Scenario,
    k: float,
    options: dict,
    safe: bool = False,
    settling: Settling = DEFAULT_SETTLING,
    priority: str = "p",
) -> StrategyResult:
    """Run `rule` on every snapshot of `scenario` at reserve k (see the module docstring);
    `options` go to the rule's target, `safe` caps Algorithm 3's limit at the physical
    capability, `priority` ("p" or "q") says which power yields where the apparent power
    binds (`limits.Capability`). The result is named `label`."""
    t0 = now()
    k = check_reserve(k)
    capability = Capability(scenario, k, safe, priority)
    plant = _Plant.of(scenario, rule.reads)
    if rule.closed_loop:
        with one_blas_thread():  # once for the loop's hundreds of flows and checks (each holds it too)
            return _settle(label, rule, options, plant, capability, settling, t0)
    n = scenario.n_snapshots
    rows = np.arange(n)
    wanted = targets(rule, plant.measure(rule.reads, rows, None), options, n)
    finite = wanted.finite
    q, p = capability.setpoints(rows, *_finite(wanted, finite))
    pf = scenario.flow(q, p)
    res = StrategyResult.from_setpoints(label, k, scenario, q, elapsed_ms(t0), power_flows=1, pf=pf, p_mw=p)
    return _no_setpoint(res, ~finite)


def _finite(wanted: Targets, finite: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The targets with every DER of a snapshot that gave a non-finite answer at Q = 0 and
    no cap (those snapshots get no setpoint: `_no_setpoint`)."""
    q = np.where(finite[:, None], wanted.q_mvar, 0.0)
    return q, None if wanted.p_max_mw is None else np.where(finite[:, None], wanted.p_max_mw, np.inf)


def _no_setpoint(res: StrategyResult, bad: np.ndarray) -> StrategyResult:
    """Snapshots where the rule gave no finite target: status "rule-non-finite", Q and
    figures NaN."""
    if bad.any():
        res.q_mvar[bad] = np.nan
        res.losses_kw[bad] = np.nan
        res.vm[bad] = np.nan
        res.excursion_mvar[bad] = np.nan
        res.status[bad] = RULE_NON_FINITE
        if res.curtailed_mw is not None:
            res.curtailed_mw[bad] = np.nan
    return res


def adapt_step_factor(alpha: np.ndarray, dv: np.ndarray, dv_old: np.ndarray) -> np.ndarray:
    """OpenDSS InvControl's `Change_deltaQ_factor`, element-wise: the new step factors from
    this step's and the previous step's voltage changes (dv_old < 0: no previous step)."""
    known = dv_old >= 0
    down = known & (alpha > 0.2)
    up = known & (alpha < 0.9)
    change = np.where(
        down & (dv > 0.8 * dv_old),
        -0.1,
        np.where(
            down & (dv > 0.6 * dv_old),
            -0.05,
            np.where(up & (dv < 0.2 * dv_old), 0.1, np.where(up & (dv < 0.4 * dv_old), 0.05, 0.0)),
        ),
    )
    return alpha + change


def _settle(
    label: str, rule: Rule, options: dict, plant: _Plant, capability: Capability, s: Settling, t0: float
) -> StrategyResult:
    """The closed-loop steady state of every snapshot (module docstring)."""
    scenario, grid = plant.scenario, plant.grid
    n_snap, n_der = scenario.n_snapshots, len(scenario.net.ders)
    every = np.arange(n_snap)
    first = grid.step(every, np.zeros((n_snap, n_der)), None, None)  # the no-action state Q_0 = 0
    state = np.array(grid.state(first))  # per snapshot, its last step (`RuleGrid`)
    converged = np.array(grid.stepped(first), dtype=bool)
    q = np.zeros((n_snap, n_der))
    moves_p = rule.curtails or capability.priority != "p"
    available = scenario.der_p_mw
    p = np.array(available, dtype=float)  # P_0 = P^C
    flows = np.ones(n_snap, dtype=np.int64)
    residual = np.full(n_snap, np.nan)
    status = np.full(n_snap, OK, dtype=object)
    alpha = np.full((n_snap, n_der), float(s.step_factor))
    dv_old = np.full((n_snap, n_der), -1.0)
    before = np.full_like(state, np.nan)  # the state before the last step
    der_prev = np.full((n_snap, n_der), np.nan)
    rows = np.flatnonzero(converged)  # a diverged no-action flow: nothing measured (pf-diverged)
    step = 0
    while rows.size:
        pf = grid.view(state[rows])
        der_vm = grid.der_vm(pf)
        asked = targets(rule, plant.measure(rule.reads, rows, pf), options, rows.size)
        finite = asked.finite
        wanted, wanted_p = capability.setpoints(rows, *_finite(asked, finite))
        dq = np.abs(wanted - q[rows]).max(axis=1, initial=0.0)
        if moves_p:
            wanted_p = available[rows] if wanted_p is None else wanted_p
            dq = np.maximum(dq, np.abs(wanted_p - p[rows]).max(axis=1, initial=0.0))
        calm = np.ones(rows.size, dtype=bool)  # no voltage moved by more than tol_v_pu in the last step
        if step:  # … asked only where the rule asks for no more change
            near = np.flatnonzero(finite & (dq <= s.tol_q_mvar))
            calm[near] = grid.voltages_within(state[rows[near]], before[rows[near]], s.tol_v_pu)
        residual[rows] = dq
        status[rows[~finite]] = RULE_NON_FINITE
        going = finite & ~((dq <= s.tol_q_mvar) & calm)
        if step == s.max_steps:
            status[rows[going]] = NOT_SETTLED
            break
        if s.adaptive and step:
            dv_der = np.abs(der_vm - der_prev[rows])
            alpha[rows] = adapt_step_factor(alpha[rows], dv_der, dv_old[rows])
            dv_old[rows] = dv_der
        rows, wanted = rows[going], wanted[going]
        if not rows.size:
            break
        q[rows] = q[rows] + alpha[rows] * (wanted - q[rows])
        if moves_p:
            assert wanted_p is not None
            p[rows] = p[rows] + alpha[rows] * (wanted_p[going] - p[rows])
        last = state[rows]
        before[rows] = last
        answer = grid.step(rows, q[rows], p[rows] if moves_p else None, last)
        der_prev[rows] = der_vm[going]
        state[rows] = grid.state(answer)
        flows[rows] += 1
        ok = grid.stepped(answer)
        converged[rows] = ok
        rows = rows[ok]  # a diverged flow stops the snapshot: pf-diverged, no figures
        step += 1
    final = grid.final(state, converged, flows)
    res = StrategyResult.from_setpoints(
        label,
        capability.k,
        scenario,
        q,
        elapsed_ms(t0),
        power_flows=flows,
        pf=final,
        status=status,
        extra={RESIDUAL: residual},
        p_mw=p if moves_p else None,
    )
    return _no_setpoint(res, status == RULE_NON_FINITE)
