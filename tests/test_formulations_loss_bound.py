"""The loss bound (`formulations.loss_bound`): sound against AC power flows on SimBench grids
(transformer iron losses, taps), never contradicting IPOPT, and changing nothing in
`acopf-paper`'s results but which solver showed the infeasibility."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.formulations import policy as policy_module
from opfbench.formulations.acopf import run_acopf
from opfbench.formulations.loss_bound import slack_import_bound, slack_must_export
from opfbench.formulations.policy import LOSS_BOUND_STATUS
from opfbench.formulations.problem import VOLTAGE_TOLERANCE, OpfProblem, slack_p_mw, snapshot_data
from opfbench.io import load_case, load_network
from opfbench.powerflow import solve_pf_batch
from opfbench.scenario import Scenario


def june_scenario(code: str, start: str, end: str) -> Scenario:
    """The grid's own profiles from `start` to `end` (local time, 15 min)."""
    case = load_case(f"simbench:{code}")
    times = pd.date_range(start, end, freq="15min", tz="Europe/Berlin")
    return Scenario.of_case(case, times)


@pytest.mark.parametrize(
    "code, surplus",  # MV-urban: two tapped transformers, and no surplus on that day
    [("1-LV-rural1--0-sw", True), ("1-MV-urban--0-sw", False)],
)
def test_the_bound_holds_at_random_ac_points_within_the_limits(code, surplus):
    scenario = june_scenario(code, "2016-06-21T04:00", "2016-06-21T20:00")
    net = scenario.net
    rng = np.random.default_rng(5)
    for k in (0.0, 0.4):
        data = snapshot_data(scenario, k)
        problem = OpfProblem.of(net, slack_export=False)
        bound = slack_import_bound(problem, data)
        for draw in range(4):  # DER Q uniform within the usable range, and at its corners
            unit = rng.uniform(-1, 1, data.q_limit.shape) if draw < 2 else rng.choice([-1.0, 1.0], data.q_limit.shape)
            q_pu = unit * data.q_limit
            pf = solve_pf_batch(net, scenario.injections(q_pu * net.base_mva))
            vm = pf.vm
            within = (
                pf.converged
                & np.all(vm >= net.vmin - VOLTAGE_TOLERANCE, axis=1)
                & np.all(vm <= net.vmax + VOLTAGE_TOLERANCE, axis=1)
            )
            slack_p = (slack_p_mw(net, pf) / net.base_mva) - data.s_fixed[:, net.slack].real  # the slack rule's P, p.u.
            assert within.mean() > 0.5
            assert np.all(slack_p[within] <= bound[within] + 1e-12), (slack_p - bound)[within].max()
    assert slack_must_export(problem, data).any() == surplus  # not vacuous: the June noon surplus


def test_no_bound_where_the_slack_may_export_or_on_a_meshed_feeder():
    net = load_network("paper33-meshed")
    scenario = Scenario(net, np.array([0.2]), net.der_rating_mw[None])
    data = snapshot_data(scenario, 0.0)
    assert np.isinf(slack_import_bound(OpfProblem.of(net, False), data)).all()
    paper = load_network("paper33")
    data = snapshot_data(Scenario(paper, np.array([0.01]), paper.der_rating_mw[None]), 0.0)
    assert slack_must_export(OpfProblem.of(paper, False), data).all()
    assert not slack_must_export(OpfProblem.of(paper, True), data).any()


def test_acopf_paper_with_the_bound_equals_it_without(monkeypatch):
    """Over a June day on 1-LV-rural1 the bound settles the infeasible daytime steps without
    IPOPT; IPOPT alone (solver "ipopt") reports them infeasible too; every result — Q,
    losses, statuses, the IPOPT steps after them (same warm starts) — is the same as
    without the bound, only the solver status says what showed the infeasibility."""
    scenario = june_scenario("1-LV-rural1--0-sw", "2016-06-21T06:00", "2016-06-21T18:00")
    options = {"slack_export": False, "fallback": "paper"}
    fast = run_acopf(scenario, 0.0, **options)
    proven = fast.extra["solver_status"] == LOSS_BOUND_STATUS
    assert 0 < proven.sum() < proven.size and np.all(fast.status[proven] == "infeasible")
    assert np.all(fast.q_mvar[proven] == 0) and np.all(fast.extra["iterations"][proven] == 0)
    ipopt = run_acopf(scenario, 0.0, solver="ipopt", **options)
    assert np.all(ipopt.status[proven] == "infeasible")
    assert list(ipopt.status) == list(fast.status)
    monkeypatch.setattr(policy_module, "slack_must_export", lambda problem, data: np.zeros(data.n_snapshots, dtype=bool))
    plain = run_acopf(scenario, 0.0, **options)
    assert not (plain.extra["solver_status"] == LOSS_BOUND_STATUS).any()
    assert list(plain.status) == list(fast.status)
    np.testing.assert_array_equal(plain.q_mvar, fast.q_mvar)
    np.testing.assert_array_equal(plain.losses_kw, fast.losses_kw)
    np.testing.assert_array_equal(plain.extra["iterations"][~proven], fast.extra["iterations"][~proven])


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
        proven = slack_must_export(OpfProblem.of(scenario.net, False), snapshot_data(scenario, k))
        ipopt = run_acopf(scenario, k, solver="ipopt", slack_export=False, fallback="paper")
        assert proven.any() and set(ipopt.status[proven]) <= {"infeasible", "solver-failed"}
        auto = run_acopf(scenario, k, slack_export=False, fallback="paper")
        assert np.all(auto.status[proven] == "infeasible") and np.all(auto.extra["solver_status"][proven] == LOSS_BOUND_STATUS)
        infeasible = ipopt.status == "infeasible"
        print(code, k, f"IPOPT infeasible {infeasible.sum()}, proven by the bound {proven.sum()}")
        assert proven.sum() >= 0.9 * infeasible.sum()
