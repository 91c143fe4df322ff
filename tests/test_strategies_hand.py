"""Local rules on feeders small enough to follow every step by hand.

Lines have r = x = 1e-4 p.u. on a 1 MVA base and every bus's active load equals its DER's
active output, so active flows are ≈ 0 and reactive flows equal the sums of downstream
reactive loads and injections up to the reactive losses Σ x·|S|²/|V|². The largest flow
here is 0.65 MVA, so those losses are below 4 lines × 1e-4 × 0.65² ≈ 1.7e-4 MVAr; the
tolerance TOL = 1e-3 MVAr is six times that and a hundred times smaller than the 0.1 MVAr
differences the assertions distinguish.
"""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario
from opfbench.strategies.meters import LocalMeters
from opfbench.strategies.paper import BACK_TO_LLMA, KEPT, LEAF, STOPPED, SUBTRACTED, lfma, lfma_step4, lfma_trace
from tests.support.feeders import radial_feeder

TOL = 1e-3  # MVAr, see module docstring

# Chain slack(0) – 1 – 2 – 3 – 4; lines 1 (1–2) and 3 (3–4) stored child → parent.
# PV units at P = 0.8·P̄, where Qmax = min(0.75·0.8, √(1 − 0.8²))·P̄ = 0.6·P̄:
# buses 1, 2: P̄ = 1 → Qmax 0.6; bus 3: P̄ = 1/3 → 0.2; bus 4 (leaf): P̄ = 0.25 → 0.15.
RATING = np.array([1.0, 1.0, 1 / 3, 0.25])
P_NOW = 0.8 * RATING
LOAD_Q = [0.0, 0.1, 0.1, 0.1, 0.35]


def chain_scenario() -> Scenario:
    net = radial_feeder(
        parent=[0, 1, 2, 3],
        load_p_mw=[0.0, *P_NOW],
        load_q_mvar=LOAD_Q,
        ders=[(b, "PV", s) for b, s in zip((1, 2, 3, 4), RATING, strict=True)],
        reversed_lines=[1, 3],
    )
    return Scenario(net, [1.0], [P_NOW])


# Expected values per k, derived by hand (d = deficit left after LLMA = 0.35 − Q^H at bus 4):
#
# k = 0: L = [0.6, 0.6, 0.2, 0.15]. Step 2: Q^H = [0.1, 0.1, 0.1, 0.15], d = 0.2, so each
#   branch node imports Q_up^H = 0.2 and exports Q_do^H = 0.2. Step 3: Q^I = [0.3, 0.3,
#   min(0.3, 0.2), 0.15]. Bus 3 still imports 0.1 (no sign change → KEPT); bus 2 feeds 0.1
#   down and exports 0.1 up (Q_up flips, Q_do does not → Q^F = 0.3 − 0.1 = 0.2); bus 1
#   receives 0.1 from bus 2 and exports 0.3 up (both flip → back to LLMA, 0.1).
# k = 0.5: L = [0.3, 0.3, 0.1, 0.075]. Q^H = [0.1, 0.1, 0.1, 0.075], d = 0.275. Q^I = [0.3,
#   0.3, 0.1, 0.075]: bus 3 imports 0.275, bus 2 imports 0.075 (both KEPT); bus 1 feeds
#   0.075 down and exports 0.125 up → Q^F = 0.3 − 0.125 = 0.175.
HAND = {
    0.0: dict(
        q_llma=[0.1, 0.1, 0.1, 0.15],
        q_up_h=[0.2, 0.2, 0.2],
        q_do_h=[0.2, 0.2, 0.2],
        q_step3=[0.3, 0.3, 0.2, 0.15],
        q_up_i=[-0.3, -0.1, 0.1],
        q_do_i=[-0.1, 0.1, 0.2],
        rule=[BACK_TO_LLMA, SUBTRACTED, KEPT, LEAF],
        q_final=[0.1, 0.2, 0.2, 0.15],
    ),
    0.5: dict(
        q_llma=[0.1, 0.1, 0.1, 0.075],
        q_up_h=[0.275] * 3,
        q_do_h=[0.275] * 3,
        q_step3=[0.3, 0.3, 0.1, 0.075],
        q_up_i=[-0.125, 0.075, 0.275],
        q_do_i=[0.075, 0.275, 0.275],
        rule=[SUBTRACTED, KEPT, KEPT, LEAF],
        q_final=[0.175, 0.3, 0.1, 0.075],
    ),
}


@pytest.mark.parametrize("k", sorted(HAND))
def test_lfma_every_step_by_hand(k: float) -> None:
    scenario = chain_scenario()
    trace = lfma_trace(scenario, k)
    want = HAND[k]
    # Step 1: the upstream line of buses 1, 2, 3 is the line to their parent (0.65 > 0.55 >
    # 0.45 > 0.35 MVAr in the no-action state); bus 4 is a leaf.
    np.testing.assert_array_equal(trace.upstream_branch[0], [0, 1, 2, -1])
    for key in ("q_llma", "q_step3", "q_final"):
        np.testing.assert_allclose(getattr(trace, key)[0], want[key], atol=TOL, err_msg=key)
    for key in ("q_up_h", "q_do_h", "q_up_i", "q_do_i"):  # measurements: branch nodes only
        np.testing.assert_allclose(getattr(trace, key)[0, :3], want[key], atol=TOL, err_msg=key)
    np.testing.assert_array_equal(trace.rule[0], want["rule"])
    # The grid answers the final setpoints: generation ≈ total reactive load, slack Q ≈ 0.
    assert abs(trace.flows[-1].slack_s_mva[0].imag) < TOL
    assert np.all(trace.diverged_step == 0)


def test_lfma_result_matches_trace_and_beats_llma_here() -> None:
    scenario = chain_scenario()
    res, trace = lfma(scenario, 0.0), lfma_trace(scenario, 0.0)
    np.testing.assert_array_equal(res.q_mvar, trace.q_final)
    assert res.power_flows.tolist() == [4] and res.status.tolist() == ["ok"]
    assert res.extra["upstream_disagreements"][0] == []
    # Q supplied next to the loads instead of through the lines: fewer losses.
    assert (
        res.losses_kw[0]
        < run_strategy("llma", scenario, 0.0).losses_kw[0]
        < run_strategy("no-action", scenario, 0.0).losses_kw[0]
    )


def test_step4_decision_table() -> None:
    # Columns = DERs: (a) no sign change, (b) Q_up flips, Q_do keeps → subtract, (c) both
    # flip → LLMA, (d) Q_do reads exactly 0 after step 3 → counts as a change → LLMA,
    # (e) subtraction beyond −L → clipped at −L, (f) leaf. Row 1: snapshot that diverged.
    q_h = np.array([[0.1, 0.1, 0.1, 0.1, -0.1, 0.05]] * 2)
    q_i = np.array([[0.3, 0.3, 0.3, 0.3, -0.2, 0.05]] * 2)
    q_up_h = np.array([[0.2, 0.2, 0.2, 0.2, 0.2, 0.0]] * 2)
    q_up_i = np.array([[0.1, -0.1, -0.3, -0.1, -0.5, 0.0]] * 2)
    q_do_h = np.array([[0.2, 0.2, 0.2, 0.2, -0.4, 0.0]] * 2)
    q_do_i = np.array([[0.2, 0.1, -0.1, 0.0, -0.1, 0.0]] * 2)
    limit = np.full((2, 6), 0.4)
    branch = np.array([True] * 5 + [False])
    q_f, rule = lfma_step4(q_h, q_i, q_up_h, q_up_i, q_do_h, q_do_i, limit, np.array([True, False]), branch)
    np.testing.assert_array_equal(rule[0], [KEPT, SUBTRACTED, BACK_TO_LLMA, BACK_TO_LLMA, SUBTRACTED, LEAF])
    np.testing.assert_allclose(q_f[0], [0.3, 0.2, 0.1, 0.1, -0.4, 0.05], atol=1e-15)
    np.testing.assert_array_equal(rule[1], [STOPPED] * 5 + [LEAF])
    np.testing.assert_array_equal(q_f[1], q_i[1])


def test_meters_read_both_line_ends_with_the_documented_signs() -> None:
    # Tree: 0 – 1, 1 – 2 (leaf), 1 – 3, 3 – 4 (leaf); line 2 (1–3) stored 3 → 1.
    net = radial_feeder(
        parent=[0, 1, 1, 3],
        load_p_mw=[0, 0, 0, 0, 0],
        load_q_mvar=[0, 0.05, 0.2, 0.1, 0.15],
        ders=[(1, "PV", 1.0), (3, "PV", 1.0)],
        reversed_lines=[2],
    )
    scenario = Scenario(net, [1.0], [[0.0, 0.0]])
    meters = LocalMeters.of(net)
    trace = lfma_trace(scenario, 1.0)  # k = 1: no reactive output at any step
    outflow = meters.outflow_q(trace.flows[0])[0]
    # Bus 1: lines 0 (import 0.5 from the slack), 1 (0.2 to bus 2), 2 (0.25 to bus 3).
    np.testing.assert_allclose(outflow[0], [-0.5, 0.2, 0.25], atol=TOL)
    # Bus 3: lines 2 (import 0.25), 3 (0.15 to bus 4); padding reads 0.
    np.testing.assert_allclose(outflow[1], [-0.25, 0.15, 0.0], atol=TOL)
    np.testing.assert_array_equal(trace.upstream_branch[0], [0, 2])
    q_up, q_do = meters.split(outflow[None], np.array([[0, 0]]))
    np.testing.assert_allclose([q_up[0], q_do[0]], [[0.5, 0.25], [0.45, 0.15]], atol=TOL)


# Algorithm 3 on one PV unit (P̄ = 1 MW) whose bus load (1 MVAr) exceeds any limit, so
# LLMA sits on the bound. Qmax(P) = min(0.75·P, √(1 − P²)):
# Qmax(0.4) = 0.3, Qmax(0.6) = 0.45, Qmax(0.8) = 0.6, Qmax(0.96) = min(0.72, 0.28) = 0.28.
P_CURRENT = [0.4, 0.6, 0.8]
P_FORECAST = [0.6, 0.4, 0.96]
ALG3 = {  # (k, safe) -> (setpoints, excursion over Qmax(P^C))
    (0.0, False): ([0.45, 0.45, 0.6], [0.15, 0.0, 0.0]),  # snapshot 0 uses the forecast limit
    (0.0, True): ([0.3, 0.45, 0.6], [0.0, 0.0, 0.0]),  # safe: capped at Qmax(P^C)
    (0.5, False): ([0.225, 0.225, 0.3], [0.0, 0.0, 0.0]),  # (1 − k)·0.45 < 0.3: no excursion
    (0.5, True): ([0.225, 0.225, 0.3], [0.0, 0.0, 0.0]),
}


@pytest.mark.parametrize("k,safe", sorted(ALG3))
def test_forecast_limits_by_hand(k: float, safe: bool) -> None:
    net = radial_feeder(parent=[0, 1], load_p_mw=[0, 0, 0], load_q_mvar=[0, 1.0, 0.1], ders=[(1, "PV", 1.0)])
    scenario = Scenario(net, np.ones(3), np.array(P_CURRENT)[:, None], np.array(P_FORECAST)[:, None])
    want_q, want_excursion = ALG3[(k, safe)]
    res = run_strategy("llma", scenario, k, safe=safe)
    np.testing.assert_allclose(res.q_mvar[:, 0], want_q, atol=1e-12)
    np.testing.assert_allclose(res.excursion_mvar, want_excursion, atol=1e-12)
    plain = run_strategy("llma", Scenario(net, np.ones(3), np.array(P_CURRENT)[:, None]), k, safe=safe)
    np.testing.assert_allclose(plain.q_mvar[:, 0], (1 - k) * np.array([0.3, 0.45, 0.6]), atol=1e-12)
