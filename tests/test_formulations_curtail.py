"""The AC OPF that may curtail (`acopf:curtail=true`, `formulations.curtail`): on paper33
with its upper voltage limit lowered to 1.03 p.u., at light load and full sun — where the
plain AC OPF has no point within the band — it curtails and holds it; its cost (losses +
curtailed power) never exceeds the plain optimum's losses; every DER stays within its
capability at the power it delivers; the relaxation's certified point and IPOPT's agree
and the bound lies below; and the plain AC OPF at the curtailed powers finds the same
losses (the curtailment's cost apart)."""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.capability import qmax
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy
from opfbench.result import INFEASIBLE, OK
from opfbench.scenario import Scenario


@pytest.fixture(scope="module")
def tight() -> Scenario:
    net = load_network("paper33")
    net = net.with_changes(vmax=np.where(np.arange(net.n_bus) != net.slack, 1.03, net.vmax))
    return Scenario(net, [1.0, 0.2, 0.3, 0.5], np.array([0.6, 1.0, 0.95, 0.85])[:, None] * net.der_rating_mw)


@pytest.mark.parametrize("k", [0.0, 0.4])
def test_curtailing_holds_the_band_where_q_alone_cannot_and_never_costs_more(tight, k):
    plain = run_strategy("acopf", tight, k)
    cut = run_strategy("acopf:curtail=true", tight, k)
    assert plain.status[1] == INFEASIBLE and cut.curtailed_mw is not None
    assert (cut.status == OK).all() and (cut.voltage_violation() <= 1e-6).all()
    cost = cut.losses_kw + cut.curtailed_kw
    assert cut.curtailed_kw[1] > 10.0  # the band is held by curtailing
    optimal = plain.status == OK
    assert (cost[optimal] <= plain.losses_kw[optimal] + 1e-4).all()
    assert (cut.lower_bound_kw <= cost * (1 + 1e-6)).all()
    net = tight.net
    delivered = tight.der_p_mw - cut.curtailed_mw
    assert (delivered <= tight.der_p_mw + 1e-12).all() and (delivered >= -1e-12).all()
    capability = (1 - k) * qmax(net.der_kinds, np.maximum(delivered, 0.0), net.der_rating_mw, net.der_s_mva)
    assert (np.abs(cut.q_mvar) <= capability + 1e-6).all()


def test_the_certified_point_is_ipopts_and_the_plain_opf_agrees_at_the_curtailed_powers(tight):
    fast = run_strategy("acopf:curtail=true", tight, 0.0)
    ipopt = run_strategy("acopf:curtail=true,solver=ipopt", tight, 0.0)
    assert fast.solver is not None and ipopt.solver is not None
    assert set(fast.solver.certified_by) >= {"socp"} and set(ipopt.solver.certified_by) == {"ipopt"}
    cost = fast.losses_kw + fast.curtailed_kw
    np.testing.assert_allclose(cost, ipopt.losses_kw + ipopt.curtailed_kw, rtol=0, atol=1e-3)
    assert fast.curtailed_mw is not None
    held = Scenario(tight.net, tight.load_scale, tight.der_p_mw - fast.curtailed_mw)
    at_those = run_strategy("acopf", held, 0.0)
    solved = at_those.status == OK  # (IPOPT may fail on a point with many voltages on their limit)
    assert solved.sum() >= 3
    np.testing.assert_allclose(at_those.losses_kw[solved], fast.losses_kw[solved], rtol=0, atol=1e-3)
