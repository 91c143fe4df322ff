"""The frontier of losses against voltage compliance (`formulations.frontier`): the AC OPF
with the band widened by ε, on paper33 with its upper voltage limit lowered to the slack's
1.0 p.u. over two hours of the paper day (the band binds the optimum at most steps):
non-increasing in ε, its bound below it, each point within its widened band, the point
at ε = 0 the `acopf` strategy's and the widest the OPF's on the widened network, steps
whose band does not bind solved once; and every built-in local rule's step on or above the
frontier point at its own compliance."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from opfbench.data import paper_day
from opfbench.formulations.frontier import COVER_PU, EPSILONS, Frontier, Part, excursion, frontier, reference, widened
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.io import load_network
from opfbench.registry.catalog import configuration, run_strategy
from opfbench.registry.references import DEFAULT_RUN
from opfbench.scenario import Scenario


@pytest.fixture(scope="module")
def tight() -> tuple[Scenario, Frontier]:
    net = load_network("paper33")
    others = np.arange(net.n_bus) != net.slack
    day = paper_day()
    rows = slice(600, 720, 4)  # 10:00–12:00, every 4th minute
    scenario = Scenario.from_profiles(
        net.with_changes(vmax=np.where(others, 1.0, net.vmax)), *(day[c].to_numpy()[rows] for c in ("load", "pv", "wind"))
    )
    return scenario, frontier(scenario, 0.0)


def test_the_frontier_falls_with_the_widening_and_bounds_hold(tight):
    scenario, front = tight
    assert front.eps.tolist() == list(EPSILONS) and front.cost_kw.shape == (scenario.n_snapshots, len(EPSILONS))
    assert not np.isnan(front.cost_kw).any()  # an optimum at every step and ε
    assert (np.diff(front.cost_kw, axis=1) <= 1e-6).all()  # a wider band never costs more
    assert (front.bound_kw <= front.cost_kw * (1 + 1e-6) + 1e-6).all()  # the relaxation's bound lies below
    assert (front.excursion_pu <= front.eps + COVER_PU).all()  # each point within its own widened band
    assert front.cost_kw[:, 0].sum() > front.cost_kw[:, -1].sum() + 1.0  # the band binds here


def test_the_frontier_points_are_the_optimum_on_the_widened_network(tight):
    scenario, front = tight
    np.testing.assert_allclose(front.cost_kw[:, 0], run_acopf(scenario, 0.0).losses_kw, rtol=0, atol=1e-9)
    for j in (3, len(EPSILONS) - 1):  # 0.01 p.u. and the physical limits alone
        res = run_acopf(replace(scenario, net=widened(scenario.net, EPSILONS[j])), 0.0)
        np.testing.assert_allclose(front.cost_kw[:, j], res.losses_kw, rtol=1e-6, atol=1e-6)
    free = (front.excursion_pu[:, 0] == front.excursion_pu[:, -1]) & (front.cost_kw[:, 0] == front.cost_kw[:, -1])
    assert not front.solved[free, 1:].any()  # a band that does not bind: solved once
    assert front.solved[:, 0].all() and front.solved[~free, -1].all()


def test_widened_keeps_one_network_per_widening_and_clips_at_the_physical_limits():
    net = load_network("paper33")
    assert widened(net, 0.0) is net and widened(net, 0.01) is widened(net, 0.01)
    np.testing.assert_allclose(widened(net, 0.01).vmax[1:], net.vmax[1:] + 0.01)
    wide, others = widened(net, math.inf), np.arange(net.n_bus) != net.slack
    assert (wide.vmin[others] == 0).all() and (wide.vmax[others] == 2.0).all() and wide.vmax[net.slack] == net.vmax[net.slack]
    vm = np.array([[1.0] * net.n_bus, [1.12] + [0.85] * (net.n_bus - 1), [np.nan] * net.n_bus])
    np.testing.assert_allclose(excursion(net, vm), [0.0, 0.05, np.nan])


def test_a_step_is_compared_with_the_smallest_widening_that_covers_it(tight):
    _, front = tight
    e = np.array([0.0, 0.001, 0.0025, 0.0025 + 0.5 * COVER_PU, 0.004, 0.07, np.nan])
    rows = Frontier(
        front.eps,
        np.tile(np.arange(7.0), (7, 1)),
        np.zeros((7, 7)),
        np.zeros((7, 7)),
        np.full((7, 7), "ok", dtype=object),
        np.ones((7, 7), bool),
    )
    assert rows.index(e).tolist() == [0, 1, 1, 1, 2, 6, -1]
    cost, bound, eps = rows.at(e)
    assert cost[:6].tolist() == [0.0, 1.0, 1.0, 1.0, 2.0, 6.0] and np.isnan(cost[6]) and np.isnan(eps[6])
    assert eps[5] == math.inf


def test_every_built_in_rule_lies_on_or_above_the_frontier_at_its_own_compliance(tight):
    """The OPF's set holds every point a rule within its limits reaches: at the smallest
    widening covering the rule's excursion, the optimum loses no more than the rule."""
    scenario, front = tight
    checked = 0
    for label in DEFAULT_RUN:
        if configuration(label).kind != "local":
            continue
        res = run_strategy(label, scenario, 0.0)
        cost, _, _ = front.at(res.voltage_violation())
        assert (res.losses_kw + res.curtailed_kw >= cost - 1e-4).all(), label
        checked += 1
    assert checked >= 8


def test_rules_that_curtail_lie_on_or_above_the_frontier_of_the_optimum_that_may_curtail():
    """paper33, upper limit 1.03 p.u., light load and full sun: Volt-Watt and reactive
    priority curtail; the optimum that may curtail (losses + curtailed power) is a frontier
    below the plain one at every ε and none of them lies below it at its own compliance."""
    net = load_network("paper33")
    net = net.with_changes(vmax=np.where(np.arange(net.n_bus) != net.slack, 1.03, net.vmax))
    scenario = Scenario(net, [0.2, 0.3, 0.5, 0.8], np.array([1.0, 0.95, 0.85, 0.7])[:, None] * net.der_rating_mw)
    plain, cutting = frontier(scenario, 0.0), frontier(scenario, 0.0, curtail=True)
    assert cutting.curtail and not plain.curtail and not np.isnan(cutting.cost_kw).any()
    assert np.isnan(plain.cost_kw[0, 0])  # no point within the band without curtailing
    both = ~np.isnan(plain.cost_kw)
    assert (cutting.cost_kw[both] <= plain.cost_kw[both] + 1e-4).all()
    curtailed = 0.0
    for label in ("volt-watt:v=1/1.03,p=1/0", "volt-var+volt-watt:vw_v=1/1.03,vw_p=1/0", "volt-var:priority=q"):
        res = run_strategy(label, scenario, 0.0)
        cost, _, _ = cutting.at(res.voltage_violation())
        assert (res.losses_kw + res.curtailed_kw >= cost - 1e-4).all(), label
        curtailed += float(res.curtailed_kw.sum())
    assert curtailed > 1.0


def test_a_reference_takes_the_curtailing_frontier_where_the_rule_curtailed(tight):
    scenario, plain = tight
    rows = np.array([1, 3, 4])
    cutting = frontier(scenario.take(rows), 0.0, curtail=True)
    e = np.zeros(scenario.n_snapshots)
    curtailed = np.zeros(scenario.n_snapshots, dtype=bool)
    curtailed[[3, 4]] = True
    ref = reference(plain, e, [(Part(cutting, rows), curtailed)])
    assert ref.curtails.tolist() == curtailed.tolist()
    np.testing.assert_array_equal(ref.cost_kw[[3, 4]], cutting.cost_kw[[1, 2], 0])
    np.testing.assert_array_equal(ref.cost_kw[~curtailed], plain.cost_kw[~curtailed, 0])
    curtailed[0] = True  # a step the curtailing frontier was not computed on
    with pytest.raises(ValueError, match="lacks a step"):
        reference(plain, e, [(Part(cutting, rows), curtailed)])


def test_an_optimum_at_a_given_reactive_limit_keeps_it_and_the_limit_stays_within_the_capability(tight):
    """The frontier at the capability a rule used (`Scenario.q_limit_mvar`, Algorithm 3's
    limit): the OPF's DER keep the given limit (here half the reserve-free capability, so the
    optimum loses more than the one at k = 0), and a limit beyond the capability is refused."""
    from opfbench.errors import InputError

    scenario, front = tight
    half = replace(scenario, q_limit_mvar=0.5 * scenario.qmax_mvar())
    res = run_acopf(half, 0.0)
    assert (np.abs(res.q_mvar) <= half.q_limit_mvar + 1e-9).all()
    assert (np.abs(res.q_mvar) >= half.q_limit_mvar - 1e-6).any()  # it binds somewhere
    assert (res.losses_kw >= front.cost_kw[:, -1] - 1e-4).all() and res.losses_kw.sum() > np.nansum(front.cost_kw[:, 0])
    assert np.array_equal(half.take(np.array([2, 5])).q_limit_mvar, half.q_limit_mvar[[2, 5]])
    with pytest.raises(InputError, match="q_limit_mvar must lie within"):
        replace(scenario, q_limit_mvar=1.5 * scenario.qmax_mvar() + 1e-3)


def test_a_proven_infeasibility_covers_every_narrower_band_with_the_answer_a_solve_gives():
    """paper33 with its lower limit raised to 0.98 p.u., 19:00–21:00: the evening steps have
    no point within the narrow bands, which the interval bounds prove; a proof at ε covers
    every smaller ε unsolved, with what solving there gives (no action, no bound)."""
    net = load_network("paper33")
    others = np.arange(net.n_bus) != net.slack
    day = paper_day()
    rows = slice(1140, 1260, 20)
    scenario = Scenario.from_profiles(
        net.with_changes(vmin=np.where(others, 0.98, net.vmin)), *(day[c].to_numpy()[rows] for c in ("load", "pv", "wind"))
    )
    front = frontier(scenario, 0.0)
    covered = (front.status == "infeasible") & ~front.solved
    covered[:, 0] = False  # ε = 0 is the acopf strategy's own answer
    assert covered.any()
    for j in np.flatnonzero(covered.any(axis=0)):
        res = run_acopf(replace(scenario, net=widened(scenario.net, EPSILONS[j])), 0.0)
        at = covered[:, j]
        assert (res.status[at] == "infeasible").all() and res.extra["proven_infeasible"][at].all()
        np.testing.assert_array_equal(front.excursion_pu[at, j], excursion(scenario.net, res.vm[at]))
        assert np.isnan(front.cost_kw[at, j]).all() and np.isnan(front.bound_kw[at, j]).all()
        assert np.isnan(res.lower_bound_kw[at]).all()
