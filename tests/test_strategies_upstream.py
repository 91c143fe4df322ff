"""LFMA step 1 — upstream detection from local measurements only — against the true
parent line (BFS from the slack) on radial feeders; disagreements on a meshed feeder are
reported in the result, not raised."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opfbench.io import load_network
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult
from opfbench.scenario import Scenario
from opfbench.strategies.paper import lfma, lfma_trace, upstream_disagreements
from tests.support.feeders import radial_feeder


def operating_points(case: str, n: int, seed: int) -> Scenario:
    """n operating points: load scale U[0.1, 2.0], each DER's P uniform in [0, rating]."""
    net = load_network(case)
    rng = np.random.default_rng(seed)
    return Scenario(net, rng.uniform(0.1, 2.0, n), rng.uniform(0, 1, (n, len(net.ders))) * net.der_rating_mw)


def true_upstream(net: Network) -> np.ndarray:
    """Parent line of each non-leaf DER bus (−1 at leaves), as LfmaTrace.upstream_branch has it."""
    return np.where(net.is_leaf[net.der_bus], -1, net.parent_branch[net.der_bus])


@pytest.mark.parametrize("case,seed", [("paper33", 1), ("case69-der", 2)])
def test_detection_equals_true_parent_on_radial_cases(case: str, seed: int) -> None:
    scenario = operating_points(case, 1000, seed)
    trace = lfma_trace(scenario, 0.0)
    assert np.all(trace.diverged_step == 0)
    assert np.any(trace.upstream_branch >= 0), "no branch-node DER: the check would be vacuous"
    np.testing.assert_array_equal(trace.upstream_branch, np.broadcast_to(true_upstream(scenario.net), trace.rule.shape))
    assert all(d == [] for d in upstream_disagreements(scenario, trace))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 12), data=st.data())
def test_detection_on_random_radial_feeders(n: int, data: st.DataObject) -> None:
    # Every bus has a reactive load > 0, so a bus's upstream line carries its own load plus
    # what all its other lines carry: the largest |Q| is strictly the upstream one.
    parent = [data.draw(st.integers(0, j - 1)) for j in range(1, n)]
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    der_buses = data.draw(st.lists(st.integers(1, n - 1), min_size=1, max_size=n - 1, unique=True))
    net = radial_feeder(
        parent,
        np.r_[0.0, rng.uniform(0, 0.2, n - 1)],
        np.r_[0.0, rng.uniform(0.01, 0.2, n - 1)],
        [(b, "PV", 0.3) for b in der_buses],
        r=rng.uniform(1e-3, 0.02, n - 1),
        x=rng.uniform(1e-3, 0.02, n - 1),
        reversed_lines=data.draw(st.lists(st.integers(0, n - 2), unique=True)),
    )
    scenario = Scenario(net, rng.uniform(0.1, 1.5, 5), rng.uniform(0, 0.3, (5, len(der_buses))))
    trace = lfma_trace(scenario, 0.0)
    np.testing.assert_array_equal(trace.upstream_branch, np.broadcast_to(true_upstream(net), trace.rule.shape))


def largest_q_line(net: Network, pf: PowerFlowResult, s: int, bus: int) -> int:
    """Reference for step 1, written independently of the meters: loop over all in-service
    lines, read Q at `bus`'s own end, keep the largest |Q|."""
    best, best_q = -1, -1.0
    for k in range(net.n_branch):
        if net.status[k] and bus in (net.f[k], net.t[k]):
            q = abs(pf.sf_mva[s, k].imag if net.f[k] == bus else pf.st_mva[s, k].imag)
            if q > best_q:
                best, best_q = k, q
    return best


def test_meshed_disagreements_are_reported_not_raised() -> None:
    scenario = operating_points("paper33-meshed", 100, 3)
    net = scenario.net
    res, trace = lfma(scenario, 0.0), lfma_trace(scenario, 0.0)
    assert net.meshed and np.all(res.status == "ok")
    der_ids = net.bus_ids[net.der_bus]
    for s in range(scenario.n_snapshots):
        detected = [largest_q_line(net, trace.flows[0], s, int(b)) for b in net.der_bus]
        np.testing.assert_array_equal(trace.upstream_branch[s], detected)
        expected = [int(b) for b, d, p in zip(der_ids, detected, net.parent_branch[net.der_bus], strict=True) if d != p]
        assert res.extra["upstream_disagreements"][s] == expected
    # The comparison is not vacuous: on this meshed feeder the largest flow is not always
    # on the BFS parent line (e.g. bus 29 next to the 600 kVAr load at bus 30).
    assert any(res.extra["upstream_disagreements"])
