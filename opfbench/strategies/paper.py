"""The paper's rules on the local-rule engine (`opfbench.strategies.rule_engine`): no action,
LLMA (Algorithm 1) and LFMA (Algorithm 2), with Algorithm 3 (forecast-aware limits)
whenever the scenario carries a forecast P^F.

All S snapshots of a scenario are processed together: every power flow — the grid's
answer after each LFMA step and the final evaluation — is one `solve_pf_batch` call.

Units and signs: Q in MVAr, positive = injected by the DER. Q_up > 0 = the DER bus
imports reactive power from its upstream line; Q_do > 0 = it exports into its other
lines (see `opfbench.strategies.meters`). Several DER at one bus share what they
compensate — the bus's load and the upstream inflow — in proportion to their ratings S̄
(`Network.der_share`): together they act as one unit of their combined rating.

Power flows counted per snapshot (`StrategyResult.power_flows`): no action 1 and LLMA 1
(the evaluation of the setpoints: open-loop rules of the engine); LFMA 4 (the no-action
state of step 1 and the answers to steps 2, 3 and 4 — the last one is the evaluation of
the final setpoints).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.capability import check_reserve
from opfbench.powerflow import PowerFlowResult
from opfbench.registry.specs import strategy
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from opfbench.strategies.limits import clip, reactive_limit
from opfbench.strategies.registration import SAFE, local_rule
from opfbench.strategies.rule_engine import Grid
from opfbench.strategies.rules import Measurements
from opfbench.timing import elapsed_ms, now

# What LFMA step 4 did at each DER (LfmaTrace.rule).
LEAF = 0  # leaf node: keeps its LLMA setpoint throughout
KEPT = 1  # Q_up did not change sign between steps 2 and 3: keep the step-3 setpoint
SUBTRACTED = 2  # Q_up changed sign, Q_do did not: Q^F = Q^I − |Q_up^I|
BACK_TO_LLMA = 3  # Q_up and Q_do both changed sign (or Q_do hit zero): Q^F = Q^H
STOPPED = 4  # a power flow of this snapshot diverged earlier: setpoint frozen


@local_rule("no-action", reads=(), uses_forecast=False, summary="every DER at Q = 0", snapshot_wise=True)
def no_action_target(m: Measurements) -> np.ndarray:
    """No action: every DER at Q = 0 MVAr."""
    return np.zeros(m.shape)


@local_rule(
    "llma",
    reads=("load",),
    summary="Algorithm 1: Q = the load's Q at the DER's own bus, within (1 − k)·Qmax",
    snapshot_wise=True,
)
def llma_target(m: Measurements) -> np.ndarray:
    """Algorithm 1, (S, n_der) MVAr: the DER's share of the reactive load at its own bus
    (the engine clips it to ±L: Q^H = min(Q_load, L) for the usual positive load)."""
    return m.load_q_mvar


def llma_setpoints(scenario: Scenario, limit_mvar: np.ndarray) -> np.ndarray:
    """Algorithm 1, (S, n_der) MVAr: Q^H = min(Q_load at the DER's own bus, L), clipped to ±L."""
    return clip(scenario.load_q_at_der_mvar(), limit_mvar)


@dataclass(frozen=True, eq=False)
class LfmaTrace:
    """Every step of Algorithm 2 over S snapshots. Arrays are (S, n_der) MVAr unless noted.

    limit: the bound L; q_llma (Q^H), q_step3 (Q^I), q_final (Q^F): setpoints after
    steps 2, 3 and 4. q_up_h / q_up_i: upstream inflow measured after steps 2 / 3
    (> 0 = importing); q_do_h / q_do_i: total outflow into the other lines (> 0 =
    exporting). upstream_branch (int): the line step 1 detected (−1 at leaf DERs and
    where the no-action flow diverged). rule (int): the step-4 outcome, one of LEAF,
    KEPT, SUBTRACTED, BACK_TO_LLMA, STOPPED. flows: the 4 batched power flows (after
    steps 1–4). diverged_step (S,) int: first step whose flow diverged (1–4), 0 if none;
    from then on the snapshot's setpoints stay as they were.
    """

    limit: np.ndarray
    q_llma: np.ndarray
    q_step3: np.ndarray
    q_final: np.ndarray
    q_up_h: np.ndarray
    q_up_i: np.ndarray
    q_do_h: np.ndarray
    q_do_i: np.ndarray
    upstream_branch: np.ndarray
    rule: np.ndarray
    flows: tuple[PowerFlowResult, ...]
    diverged_step: np.ndarray


def lfma_step4(
    q_h: np.ndarray,
    q_i: np.ndarray,
    q_up_h: np.ndarray,
    q_up_i: np.ndarray,
    q_do_h: np.ndarray,
    q_do_i: np.ndarray,
    limit: np.ndarray,
    running: np.ndarray,
    branch_node: np.ndarray,
    share: np.ndarray | float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """LFMA step 4: (Q^F, rule), both (S, n_der), from the setpoints and measurements of
    steps 2 (H) and 3 (I). `running` (S,) marks the snapshots whose flows all converged so
    far (the others are STOPPED); `branch_node` (n_der,) the non-leaf DER buses (LEAF);
    `share` (n_der,) each DER's share of its bus (`Network.der_share`): what it subtracts
    of the bus's inflow.

    Q_up changed sign iff Q_up^H·Q_up^I < 0; Q_do kept its sign iff Q_do^H·Q_do^I > 0 (a
    zero reading counts as a change). Subtracting |Q_up^I| is clipped to −L: on radial
    feeders with inductive loads it never gets there, on meshed or capacitive ones it can.
    """
    leaf = np.broadcast_to(~branch_node, limit.shape)
    stopped = ~np.asarray(running)[:, None] & ~leaf
    flipped = q_up_h * q_up_i < 0
    do_kept = q_do_h * q_do_i > 0
    rule = np.select([leaf, stopped, ~flipped, do_kept], [LEAF, STOPPED, KEPT, SUBTRACTED], BACK_TO_LLMA)
    q_f = np.select([rule == SUBTRACTED, rule == BACK_TO_LLMA], [clip(q_i - share * np.abs(q_up_i), limit), q_h], q_i)
    return q_f, rule


def lfma_trace(scenario: Scenario, k: float = 0.0, safe: bool = False) -> LfmaTrace:
    """Run Algorithm 2 step by step; each step is answered by one batched power flow."""
    net = scenario.net
    grid = Grid(scenario)
    meters = grid.meters
    limit = reactive_limit(scenario, k, safe)
    q_load = scenario.load_q_at_der_mvar()  # each DER's share of its bus's load
    share = net.der_share  # … and of the inflow its bus's meters read
    branch_node = ~net.is_leaf[net.der_bus]  # (n_der,): more than one incident line

    def answer(q: np.ndarray) -> np.ndarray:
        """Apply setpoints q, let the grid answer, return the reactive meter readings."""
        return meters.outflow_q(grid.answer(q))

    def running() -> np.ndarray:
        return (grid.diverged == 0)[:, None]

    # Step 1: no action; each bus takes the line with the largest |Q| as upstream.
    q_none = np.zeros_like(limit)
    position = meters.detect_upstream(answer(q_none))
    upstream = np.where(running() & branch_node, meters.upstream_branch(position), -1)
    # Step 2: LLMA everywhere.
    q_h = np.where(running(), llma_setpoints(scenario, limit), q_none)
    q_up_h, q_do_h = meters.split(answer(q_h), position)
    # Step 3: branch nodes add the measured upstream inflow.
    q_i = np.where(running() & branch_node, clip(q_load + share * q_up_h, limit), q_h)
    q_up_i, q_do_i = meters.split(answer(q_i), position)
    # Step 4: where Q_up changed sign, subtract |Q_up^I| or return to LLMA.
    q_f, rule = lfma_step4(q_h, q_i, q_up_h, q_up_i, q_do_h, q_do_i, limit, grid.diverged == 0, branch_node, share)
    answer(q_f)
    return LfmaTrace(limit, q_h, q_i, q_f, q_up_h, q_up_i, q_do_h, q_do_i, upstream, rule, tuple(grid.flows), grid.diverged)


def upstream_disagreements(scenario: Scenario, trace: LfmaTrace) -> np.ndarray:
    """(S,) object array: per snapshot, the external bus numbers of the non-leaf DERs whose
    detected upstream line differs from the true one (BFS from the slack); None where the
    no-action flow diverged. On a radial feeder with a positive reactive load at every DER bus
    the lists are empty (the upstream line carries that load plus all the other lines carry)."""
    net = scenario.net
    true_up = net.parent_branch[net.der_bus]
    wrong = (trace.upstream_branch >= 0) & (trace.upstream_branch != true_up)
    der_ids = net.bus_ids[net.der_bus]
    out = np.empty(scenario.n_snapshots, dtype=object)
    for s in range(scenario.n_snapshots):
        out[s] = None if trace.diverged_step[s] == 1 else [int(b) for b in der_ids[wrong[s]]]
    return out


@strategy(
    "lfma",
    kind="local",
    summary="Algorithm 2: LLMA plus the measured upstream Q inflow, sign-change rules",
    reads=("load", "flows"),
    options=(SAFE,),
    uses_forecast=True,
    snapshot_wise=True,
)
def lfma(scenario: Scenario, k: float = 0.0, safe: bool = False) -> StrategyResult:
    """LFMA (Algorithm 2) with the bound L of `reactive_limit`. Snapshots whose power flow
    diverged at any step get status "pf-diverged" and NaN losses. extra: `diverged_step`
    (S,) and `upstream_disagreements` (S,) (see `upstream_disagreements`)."""
    t0 = now()
    k = check_reserve(k)
    trace = lfma_trace(scenario, k, safe)
    final = trace.flows[-1]
    completed = PowerFlowResult(final.net, final.v, trace.diverged_step == 0, final.iterations)
    extra = {"diverged_step": trace.diverged_step, "upstream_disagreements": upstream_disagreements(scenario, trace)}
    return StrategyResult.from_setpoints(
        "lfma", k, scenario, trace.q_final, elapsed_ms(t0), power_flows=len(trace.flows), pf=completed, extra=extra
    )
