"""Properties of LLMA/LFMA on random radial feeders and on `paper33` (radial and meshed) at
random operating points: setpoints within their limits, k = 1 is exactly no action, every power flow of
every step converges, leaves keep LLMA, batching does not mix snapshots."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opfbench.capability import qmax
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario
from opfbench.strategies.paper import lfma, lfma_trace
from tests.support.feeders import radial_feeder

SNAPSHOTS = 4
EPS = 1e-12  # MVAr: round-off allowance of the bound checks


@st.composite
def random_scenarios(draw) -> Scenario:
    """A random radial feeder (3–10 buses, r and x up to 0.02 p.u. on 1 MVA, loads up to
    0.2 MW/MVAr per bus) with 1–4 DER units and SNAPSHOTS random operating points."""
    n = draw(st.integers(3, 10))
    parent = [draw(st.integers(0, j - 1)) for j in range(1, n)]
    reversed_lines = draw(st.lists(st.integers(0, n - 2), unique=True))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    der_buses = draw(st.lists(st.integers(1, n - 1), min_size=1, max_size=min(4, n - 1), unique=True))
    ders = [(b, draw(st.sampled_from(["PV", "DFIG"])), float(rng.uniform(0.05, 0.5))) for b in der_buses]
    net = radial_feeder(
        parent,
        np.r_[0.0, rng.uniform(0, 0.2, n - 1)],
        np.r_[0.0, rng.uniform(0, 0.2, n - 1)],
        ders,
        r=rng.uniform(1e-3, 0.02, n - 1),
        x=rng.uniform(1e-3, 0.02, n - 1),
        reversed_lines=reversed_lines,
    )
    rating = net.der_rating_mw
    p_now = rng.uniform(0, 1, (SNAPSHOTS, len(ders))) * rating
    p_fc = rng.uniform(0, 1, (SNAPSHOTS, len(ders))) * rating if draw(st.booleans()) else None
    return Scenario(net, rng.uniform(0, 1.5, SNAPSHOTS), p_now, p_fc)


def allowed_bound(scenario: Scenario, k: float, safe: bool) -> np.ndarray:
    """|Q| bound computed from the capability curves directly (not via the rules' code):
    (1 − k)·Qmax(P^C); with a forecast (1 − k)·max(Qmax(P^C), Qmax(P^F)); safe caps it at Qmax(P^C)."""
    net = scenario.net
    now = qmax(net.der_kinds, scenario.der_p_mw, net.der_rating_mw)
    if scenario.der_p_forecast_mw is None:
        return (1 - k) * now
    bound = (1 - k) * np.maximum(now, qmax(net.der_kinds, scenario.der_p_forecast_mw, net.der_rating_mw))
    return np.minimum(bound, now) if safe else bound


def check_rules(scenario: Scenario, k: float, safe: bool) -> None:
    net = scenario.net
    bound = allowed_bound(scenario, k, safe)
    trace = lfma_trace(scenario, k, safe)
    assert all(np.all(pf.converged) for pf in trace.flows), "a power flow after some LFMA step diverged"
    assert np.all(trace.diverged_step == 0)
    for q in (trace.q_llma, trace.q_step3, trace.q_final):
        assert np.all(np.abs(q) <= bound + EPS)
    leaf = net.is_leaf[net.der_bus]
    np.testing.assert_array_equal(trace.q_final[:, leaf], trace.q_llma[:, leaf])
    res_llma, res_lfma = run_strategy("llma", scenario, k, safe=safe), lfma(scenario, k, safe=safe)
    np.testing.assert_array_equal(res_lfma.q_mvar, trace.q_final)
    q_load = scenario.load_scale[:, None] * net.load_q_mvar[net.der_bus]
    np.testing.assert_allclose(res_llma.q_mvar, np.minimum(q_load, bound), rtol=0, atol=EPS)
    for res in (res_llma, res_lfma):
        assert np.all(res.status == "ok") and np.all(np.isfinite(res.losses_kw))
        if scenario.der_p_forecast_mw is None or safe:
            assert np.all(res.excursion_mvar == 0.0)


@settings(max_examples=100, deadline=None)
@given(scenario=random_scenarios(), k=st.floats(0, 1), safe=st.booleans())
def test_rules_on_random_radial_feeders(scenario: Scenario, k: float, safe: bool) -> None:
    check_rules(scenario, k, safe)


@settings(max_examples=50, deadline=None)
@given(scenario=random_scenarios())
def test_k_one_is_exactly_no_action(scenario: Scenario) -> None:
    reference = run_strategy("no-action", scenario, 0.0)
    for rule in ("llma", "lfma"):
        for safe in (False, True):
            res = run_strategy(rule, scenario, 1.0, safe=safe)
            assert np.all(res.q_mvar == 0.0)
            np.testing.assert_allclose(res.losses_kw, reference.losses_kw, rtol=0, atol=1e-6)  # warm-started flows


def paper33_scenario(seed: int, n: int = 200, forecast: bool = False, case: str = "paper33") -> Scenario:
    net = load_network(case)
    rng = np.random.default_rng(seed)
    rating = net.der_rating_mw
    p_fc = rng.uniform(0, 1, (n, len(rating))) * rating if forecast else None
    return Scenario(net, rng.uniform(0.2, 1.8, n), rng.uniform(0, 1, (n, len(rating))) * rating, p_fc)


@pytest.mark.parametrize("case", ["paper33", "paper33-meshed"])
@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.floats(0, 1), forecast=st.booleans(), safe=st.booleans())
def test_rules_on_paper33_random_operating_points(case: str, seed: int, k: float, forecast: bool, safe: bool) -> None:
    check_rules(paper33_scenario(seed, forecast=forecast, case=case), k, safe)


def test_batch_equals_one_snapshot_at_a_time() -> None:
    scenario = paper33_scenario(7, n=12, forecast=True)
    batch = lfma(scenario, 0.3)
    for i in range(scenario.n_snapshots):
        single = lfma(scenario.take(slice(i, i + 1)), 0.3)
        np.testing.assert_allclose(single.q_mvar[0], batch.q_mvar[i], atol=1e-9)
        np.testing.assert_allclose(single.losses_kw[0], batch.losses_kw[i], rtol=1e-9)
