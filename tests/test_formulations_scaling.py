"""The DistFlow cone's per-branch scaling (`distflow.branch_scale`): the same relaxation,
solved to its optimum on the large replicated feeders where the unscaled cone stalls."""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.bench.pf_large import day96
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.models import distflow
from opfbench.formulations.models.distflow import branch_scale
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.policy import CERTIFY_RTOL
from opfbench.formulations.problem import snapshot_data
from opfbench.io import load_network
from opfbench.scenario import Scenario


def test_branch_scale_is_the_power_below_each_branch():
    net = load_network("paper33")
    s = branch_scale(net) * net.base_mva  # MVA
    head = np.flatnonzero(net.parent == net.slack)
    total = max(np.abs(net.load_p_mw + 1j * net.load_q_mvar).sum(), net.der_rating_mw.sum())
    assert s[head].sum() == pytest.approx(total)
    leaves = np.flatnonzero(net.is_leaf & ~np.isin(np.arange(net.n_bus), net.der_bus))
    assert leaves.size
    np.testing.assert_allclose(s[leaves], np.maximum(np.abs(net.load_p_mw + 1j * net.load_q_mvar)[leaves], 1e-3 * s.max()))


@pytest.mark.parametrize("case", ["paper33", "case141-der"])
def test_scaling_leaves_the_relaxation_unchanged(case, monkeypatch):
    """Any α > 0 describes the same cone: the bound with the scaling equals the textbook
    (unscaled, α = 1) cone's."""
    net = load_network(case)
    rng = np.random.default_rng(3)
    scenario = Scenario(net, rng.uniform(0.4, 1.2, 6), rng.uniform(0.0, 1.0, (6, len(net.ders))) * net.der_rating_mw)
    data = snapshot_data(scenario, 0.2)
    scaled = build_problem_model("relaxation", net)
    monkeypatch.setattr(distflow, "branch_scale", lambda n: np.ones(n.n_bus))
    textbook = build_problem_model("relaxation", net)
    for i in range(scenario.n_snapshots):
        a, b = (r.solve(data.s_fixed[i], data.q_limit[i]) for r in (scaled, textbook))
        assert a.optimal and b.optimal
        assert a.objective_kw == pytest.approx(b.objective_kw, rel=1e-6)


def test_feeder1k_snapshot_the_unscaled_cone_left_uncertified():
    """feeder1k, 15-min step 85 of the paper day, k = 0: unscaled, Clarabel ended
    "AlmostSolved" 0.5 % below the optimum and IPOPT had to run; scaled, the SOCP's
    point is certified and agrees with IPOPT's."""
    one = day96("feeder1k").take(slice(85, 86))
    fast = run_acopf(one, 0.0)
    assert fast.solver.certified_by[0] == "socp" and fast.extra["socp_status"][0] == "Solved"
    assert abs(fast.losses_kw[0] - fast.lower_bound_kw[0]) <= CERTIFY_RTOL * fast.lower_bound_kw[0]
    ipopt = run_acopf(one, 0.0, solver="ipopt")
    assert ipopt.status[0] == "ok"
    assert ipopt.losses_kw[0] == pytest.approx(fast.losses_kw[0], rel=1e-6)


@pytest.mark.slow
def test_feeder10k_noon_is_certified_by_the_socp():
    day = day96("feeder10k")
    noon = int(np.argmax(day.der_p_mw.sum(axis=1)))
    res = run_acopf(day.take(slice(noon, noon + 1)), 0.0)
    assert res.solver.certified_by[0] == "socp" and res.extra["socp_status"][0] == "Solved"
    assert bool(res.extra["ac_feasible"][0])
    assert abs(res.losses_kw[0] - res.lower_bound_kw[0]) <= CERTIFY_RTOL * res.lower_bound_kw[0]
