"""The interval bounds' proofs of infeasibility (`formulations.infeasibility`): sound against
AC power flows on SimBench grids (transformer iron losses, taps), never contradicting
IPOPT, and changing nothing in the AC OPF's results but which solver showed the
infeasibility."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.formulations import runner as acopf_module
from opfbench.formulations.infeasibility import SLACK_MUST_EXPORT, VOLTAGES_OUT_OF_REACH, flow_bounds, proven_infeasible
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.problem import VOLTAGE_TOLERANCE, OpfProblem, slack_p_mw, snapshot_data
from opfbench.io import load_case, load_network
from opfbench.powerflow import solve_pf_batch
from opfbench.scenario import Scenario


def june_scenario(code: str, start: str, end: str) -> Scenario:
    """The grid's own profiles from `start` to `end` (local time, 15 min)."""
    case = load_case(f"simbench:{code}")
    times = pd.date_range(start, end, freq="15min", tz="Europe/Berlin")
    return Scenario.of_case(case, times)


def within_limits(net, pf) -> np.ndarray:
    vm = pf.vm
    return pf.converged & np.all(vm >= net.vmin - VOLTAGE_TOLERANCE, axis=1) & np.all(vm <= net.vmax + VOLTAGE_TOLERANCE, axis=1)


@pytest.mark.parametrize(
    "code, surplus",  # MV-urban: two tapped transformers, and no surplus on that day
    [("1-LV-rural1--0-sw", True), ("1-MV-urban--0-sw", False)],
)
def test_the_bounds_hold_at_random_ac_points_within_the_limits(code, surplus):
    """Every AC point within the limits (DER Q uniform in its usable range, and at its
    corners) has its slack P below the bound and every |V|² within the bounds' intervals."""
    scenario = june_scenario(code, "2016-06-21T04:00", "2016-06-21T20:00")
    net = scenario.net
    rng = np.random.default_rng(5)
    for k in (0.0, 0.4):
        data = snapshot_data(scenario, k)
        problem = OpfProblem.of(net, slack_export=False)
        bounds = flow_bounds(problem, data)
        assert not bounds.out_of_reach.any()
        for draw in range(4):
            unit = rng.uniform(-1, 1, data.q_limit.shape) if draw < 2 else rng.choice([-1.0, 1.0], data.q_limit.shape)
            pf = solve_pf_batch(net, scenario.injections(unit * data.q_limit * net.base_mva))
            within = within_limits(net, pf)
            slack_p = (slack_p_mw(net, pf) / net.base_mva) - data.s_fixed[:, net.slack].real  # the slack rule's P, p.u.
            assert within.mean() > 0.5
            assert np.all(slack_p[within] <= bounds.slack_p_hi[within] + 1e-12), (slack_p - bounds.slack_p_hi)[within].max()
            v = pf.vm[within] ** 2
            assert np.all(v >= bounds.v_lo[within] - 1e-12) and np.all(v <= bounds.v_hi[within] + 1e-12)
    assert (proven_infeasible(problem, data) == SLACK_MUST_EXPORT).any() == surplus  # not vacuous: the June noon surplus


def test_the_bounds_hold_with_taps_at_either_end_charging_and_shunts():
    """paper33 with a tap on a branch written parent → child, another on one written child →
    parent (so the child is the tap's side), line charging, bus shunts and a conductance:
    random loads, DER output and Q; every AC point within the limits lies within the bounds."""
    base = load_network("paper33")
    f, t, tap = base.f.copy(), base.t.copy(), base.tap.copy()
    f[7], t[7] = base.t[7], base.f[7]  # branch 7 written child → parent
    tap[[2, 7]] = [0.97, 1.03]
    gs, bs = base.gs_mw.copy(), base.bs_mvar.copy()
    gs[12], bs[20] = 0.01, 0.2
    g = np.zeros(base.n_branch)
    g[2] = 1e-3
    net = base.with_changes(f=f, t=t, tap=tap, b=np.full(base.n_branch, 1e-4), gs_mw=gs, bs_mvar=bs, g=g)
    rng = np.random.default_rng(9)
    n = 60
    scenario = Scenario(net, rng.uniform(0.1, 1.3, n), rng.uniform(0, 1, (n, len(net.ders))) * net.der_rating_mw)
    data = snapshot_data(scenario, 0.0)
    bounds = flow_bounds(OpfProblem.of(net, slack_export=False), data)
    unit = rng.choice([-1.0, 1.0], data.q_limit.shape) * rng.uniform(0.5, 1, data.q_limit.shape)
    pf = solve_pf_batch(net, scenario.injections(unit * data.q_limit * net.base_mva))
    within = within_limits(net, pf)
    assert within.mean() > 0.5
    slack_p = (slack_p_mw(net, pf) / net.base_mva) - data.s_fixed[:, net.slack].real
    assert np.all(slack_p[within] <= bounds.slack_p_hi[within] + 1e-12)
    v = pf.vm[within] ** 2
    assert np.all(v >= bounds.v_lo[within] - 1e-12) and np.all(v <= bounds.v_hi[within] + 1e-12)
    assert not bounds.out_of_reach[within].any()


def test_no_proof_on_a_meshed_feeder_and_no_slack_rule_where_the_slack_may_export():
    net = load_network("paper33-meshed")
    data = snapshot_data(Scenario(net, np.array([0.2]), net.der_rating_mw[None]), 0.0)
    assert list(proven_infeasible(OpfProblem.of(net, False), data)) == [""]
    paper = load_network("paper33")
    data = snapshot_data(Scenario(paper, np.array([0.01]), paper.der_rating_mw[None]), 0.0)
    assert list(proven_infeasible(OpfProblem.of(paper, False), data)) == [SLACK_MUST_EXPORT]
    assert list(proven_infeasible(OpfProblem.of(paper, True), data)) == [""]


def _without_proofs(monkeypatch) -> None:
    monkeypatch.setattr(acopf_module, "proven_infeasible", lambda problem, data: np.full(data.n_snapshots, "", dtype=object))


def _same_results(fast, plain, proven) -> None:
    """`fast` (with the proofs) and `plain` (without) agree on everything but the solver
    status and iteration count of the proven steps."""
    assert list(plain.status) == list(fast.status)
    np.testing.assert_array_equal(plain.q_mvar, fast.q_mvar)
    np.testing.assert_array_equal(plain.losses_kw, fast.losses_kw)
    np.testing.assert_array_equal(plain.solver.iterations[~proven], fast.solver.iterations[~proven])
    assert list(plain.solver.solver_status[~proven]) == list(fast.solver.solver_status[~proven])


def test_acopf_paper_with_the_proofs_equals_it_without(monkeypatch):
    """Over a June day on 1-LV-rural1 the slack bound settles the infeasible daytime steps
    without IPOPT; IPOPT alone (solver "ipopt") reports them infeasible too; every result
    — Q, losses, statuses, the IPOPT steps after them (same warm starts) — is the same as
    without the proofs, only the solver status says what showed the infeasibility."""
    scenario = june_scenario("1-LV-rural1--0-sw", "2016-06-21T06:00", "2016-06-21T18:00")
    options = {"slack_export": False, "fallback": "paper"}
    fast = run_acopf(scenario, 0.0, **options)
    proven = fast.solver.solver_status == SLACK_MUST_EXPORT
    assert 0 < proven.sum() < proven.size and np.all(fast.status[proven] == "infeasible")
    assert np.all(fast.q_mvar[proven] == 0) and np.all(fast.solver.iterations[proven] == 0)
    ipopt = run_acopf(scenario, 0.0, solver="ipopt", **options)
    assert np.all(ipopt.status[proven] == "infeasible")
    assert list(ipopt.status) == list(fast.status)
    _without_proofs(monkeypatch)
    _same_results(fast, run_acopf(scenario, 0.0, **options), proven)


def test_a_voltage_limit_out_of_reach(monkeypatch):
    """1-LV-semiurb5: SimBench gives two LV buses |V| ≤ 1.01 p.u. behind a 1.025 p.u.
    slack; on a June day and night no AC point reaches that. The bounds prove it at every
    step (for the AC OPF with or without the slack rule); IPOPT reports infeasibility
    there too, with the same results otherwise; no random point is within the limits."""
    night = june_scenario("1-LV-semiurb5--0-sw", "2016-06-21T02:00", "2016-06-21T02:15")
    day = june_scenario("1-LV-semiurb5--0-sw", "2016-06-21T13:00", "2016-06-21T13:15")
    net = day.net
    for s in (night, day):
        data = snapshot_data(s, 0.0)
        for export in (True, False):
            assert set(proven_infeasible(OpfProblem.of(net, export), data)) == {VOLTAGES_OUT_OF_REACH}
        unit = np.random.default_rng(2).uniform(-1, 1, data.q_limit.shape)
        assert not within_limits(net, solve_pf_batch(net, s.injections(unit * data.q_limit * net.base_mva))).any()
    fast = run_acopf(day, 0.0)
    assert set(fast.solver.solver_status) == {VOLTAGES_OUT_OF_REACH} and set(fast.status) == {"infeasible"}
    ipopt = run_acopf(day, 0.0, solver="ipopt")
    assert set(ipopt.status) == {"infeasible"} and set(ipopt.solver.solver_status) <= {
        "Infeasible_Problem_Detected → Infeasible_Problem_Detected",
        "Infeasible_Problem_Detected",
    }
    _without_proofs(monkeypatch)
    _same_results(fast, run_acopf(day, 0.0), np.ones(day.n_snapshots, dtype=bool))


@pytest.mark.slow
@pytest.mark.parametrize("code", ["1-MV-rural--0-sw", "1-LV-rural3--0-sw"])
def test_the_bound_never_contradicts_ipopt_over_a_june_day(code):
    """IPOPT on every step (solver "ipopt"), k 0 and 0.4: where the bound proves the
    paper's problem infeasible IPOPT never finds a point (it reports infeasibility, or
    fails otherwise: 1-LV-rural3, k 0.4, 13:00 runs out of iterations — "solver-failed",
    which the bound makes "infeasible" under solver "auto"), and the bound covers nearly
    every step IPOPT reports infeasible."""
    scenario = june_scenario(code, "2016-06-22T00:00", "2016-06-22T23:45")
    for k in (0.0, 0.4):
        proven = proven_infeasible(OpfProblem.of(scenario.net, False), snapshot_data(scenario, k)) != ""
        ipopt = run_acopf(scenario, k, solver="ipopt", slack_export=False, fallback="paper")
        assert proven.any() and set(ipopt.status[proven]) <= {"infeasible", "solver-failed"}
        auto = run_acopf(scenario, k, slack_export=False, fallback="paper")
        assert np.all(auto.status[proven] == "infeasible") and np.all(auto.solver.solver_status[proven] == SLACK_MUST_EXPORT)
        infeasible = ipopt.status == "infeasible"
        print(code, k, f"IPOPT infeasible {infeasible.sum()}, proven by the bound {proven.sum()}")
        assert proven.sum() >= 0.9 * infeasible.sum()
