"""The AC OPF beats every feasible point: checked against no action on random scenarios."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from opfbench.errors import InputError
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from tests.support.dominance import opf_dominance


def no_action(scenario: Scenario) -> StrategyResult:
    q = np.zeros((scenario.n_snapshots, len(scenario.net.ders)))
    return StrategyResult.from_setpoints("no-action", 0.0, scenario, q, wall_ms=0.0)


@pytest.fixture(scope="module")
def random60():
    net = load_network("paper33")
    rng = np.random.default_rng(2024)
    n = 60
    return Scenario(net, rng.uniform(0.2, 1.4, n), rng.uniform(0.0, 1.0, (n, 5)) * net.der_rating_mw)


@pytest.mark.parametrize("k", [0.0, 0.6])
def test_acopf_never_worse_than_no_action(random60, k):
    opf = run_acopf(random60, k)
    report = opf_dominance(opf, no_action(random60), random60)
    assert report.ok, report.violations
    assert report.compared >= 50 and report.opf_unsolved == 0
    assert report.compared + report.other_infeasible == random60.n_snapshots
    # Where Q = 0 meets the limits it bounds the optimum from above.
    baseline = no_action(random60).losses_kw
    assert np.all(opf.losses_kw <= baseline + 1e-3)


@pytest.mark.parametrize("case", ["paper33", "case69-der"])
@pytest.mark.parametrize("k", [0.0, 0.4, 0.8])
def test_acopf_never_worse_than_the_local_rules(case, k):
    """≥ 50 random scenarios: AC OPF ≤ LLMA and LFMA (under the same k) wherever the
    rule's point is voltage-feasible. Exceptions would be listed with their scenario."""
    net = load_network(case)
    rng = np.random.default_rng(11)
    n = 60
    scenario = Scenario(net, rng.uniform(0.2, 1.4, n), rng.uniform(0.0, 1.0, (n, 5)) * net.der_rating_mw)
    opf = run_acopf(scenario, k)
    for rule in ("llma", "lfma"):
        other = run_strategy(rule, scenario, k)
        report = opf_dominance(opf, other, scenario)
        exceptions = [(i, scenario.load_scale[i], scenario.der_p_mw[i].round(3).tolist(), a, b) for i, a, b in report.violations]
        assert report.ok, f"{rule}: OPF lost at (snapshot, load scale, DER MW, OPF kW, rule kW) {exceptions}"
        assert report.compared >= 50 and report.opf_unsolved == 0


def test_dominance_detects_a_point_that_beats_a_bad_opf(random60):
    opf = run_acopf(random60, 0.0)
    worse = replace(opf, losses_kw=opf.losses_kw + 5.0)  # pretend the OPF were 5 kW off
    report = opf_dominance(worse, no_action(random60), random60)
    assert not report.ok and len(report.violations) > 0


def test_dominance_refuses_mismatched_inputs(random60):
    opf = run_acopf(random60.take(slice(0, 3)), 0.0)
    with pytest.raises(InputError, match="snapshot counts"):
        opf_dominance(opf, no_action(random60), random60)
    with pytest.raises(InputError, match="acopf"):
        opf_dominance(no_action(random60), opf, random60)
