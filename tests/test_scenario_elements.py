"""Per-element scenarios (every load's own P and Q) and the generic inverter DER kind:
the same accessors serve both load forms, and every strategy runs on them."""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.capability import INVERTER_TAN_PHI_MAX, inverter_qmax, qmax
from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.network import DER
from opfbench.powerflow import solve_pf_batch
from opfbench.registry.catalog import run_strategy
from opfbench.registry.references import DEFAULT_RUN
from opfbench.scenario import Scenario


def _split(net):
    """paper33 with every bus's load split into two elements (60/40) at the same bus."""
    return net.with_changes(load_bus=np.repeat(net.load_bus, 2))


def test_per_load_scenario_equals_load_scale_when_it_is_one():
    net = load_network("paper33")
    scale = np.array([0.6, 0.9, 1.0])
    scaled = Scenario(net, scale, np.full((3, 5), 0.3))
    split = _split(net)
    p, q = net.load_p_mw[net.load_bus], net.load_q_mvar[net.load_bus]
    share = np.tile([0.6, 0.4], net.n_load)
    per_load = Scenario.from_series(
        split, scale[:, None] * np.repeat(p, 2) * share, scale[:, None] * np.repeat(q, 2) * share, np.full((3, 5), 0.3)
    )
    q_der = np.full((3, 5), 0.05)
    assert np.allclose(per_load.injections(q_der), scaled.injections(q_der), atol=1e-15)
    assert np.allclose(per_load.bus_load_mva(), scaled.bus_load_mva(), atol=1e-15)
    assert np.allclose(per_load.load_q_at_der_mvar(), scaled.load_q_at_der_mvar(), atol=1e-15)
    assert np.allclose(per_load.load_p_at_der_mw(), scaled.load_p_at_der_mw(), atol=1e-15)
    for name in DEFAULT_RUN:  # every strategy reads the loads through the accessors
        a, b = run_strategy(name, scaled, 0.2), run_strategy(name, per_load, 0.2)
        assert np.allclose(a.losses_kw, b.losses_kw, rtol=1e-6), name


def test_per_load_values_may_be_negative_and_sum_per_bus():
    net = _split(load_network("paper33"))
    p = np.full((1, net.n_load), 0.01)
    q = np.full((1, net.n_load), -0.004)  # capacitive: the elements inject Q
    sc = Scenario.from_series(net, p, q, np.zeros((1, 5)))
    bus = sc.bus_load_mva()[0]
    assert np.allclose(bus[net.load_bus[::2]], 0.02 - 0.008j) and sc.load_q_at_der_mvar().max() < 0
    assert solve_pf_batch(net, sc.injections(np.zeros((1, 5)))).converged.all()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"load_p_mw": np.zeros((2, 3)), "load_q_mvar": np.zeros((2, 3))}, r"shape \(S, n_load\)"),
        ({"load_p_mw": np.zeros((2, 32))}, "both load_p_mw and load_q_mvar"),
        ({"load_p_mw": np.full((2, 32), np.nan), "load_q_mvar": np.zeros((2, 32))}, "NaN or inf"),
    ],
)
def test_bad_per_load_input(kwargs, message):
    net = load_network("paper33")
    with pytest.raises(InputError, match=message):
        Scenario(net, None, np.zeros((2, 5)), **kwargs)


def test_load_scale_and_per_load_together_refused():
    net = load_network("paper33")
    with pytest.raises(InputError, match="either load_scale or the per-load"):
        Scenario(net, np.ones(1), np.zeros((1, 5)), load_p_mw=np.zeros((1, 32)), load_q_mvar=np.zeros((1, 32)))


def test_inverter_capability():
    s = np.array(1.0 / 0.9)  # S̄ = P̄/0.90
    p = np.array([0.0, 0.5, 1.0, -1e-5])
    q = inverter_qmax(p, np.ones(4), np.full(4, s))
    assert q[:3] == pytest.approx(p[:3] * INVERTER_TAN_PHI_MAX)  # the cos φ 0.90 limit binds up to P̄
    assert q[2] == pytest.approx(np.sqrt(s**2 - 1.0)) and q[3] == pytest.approx(1e-5 * INVERTER_TAN_PHI_MAX)
    assert inverter_qmax(np.array([1.0]), np.ones(1), np.ones(1))[0] == 0.0  # S̄ = P̄: nothing left at full output
    night = inverter_qmax(np.array([0.0]), np.ones(1), np.array([s]), night=True)
    assert night[0] == pytest.approx(s)
    with pytest.raises(InputError, match="≥ −S̄"):
        inverter_qmax(np.array([-2.0]), np.ones(1), np.ones(1))


def test_inverter_units_in_a_scenario_and_night_modes():
    base = load_network("case33bw")
    ders = (
        DER(base.index_of(18), "inverter", 0.5, 0.5 / 0.9, "solar"),
        DER(base.index_of(25), "inverter", 0.5, 0.5 / 0.9, "wind"),
    )
    net = base.with_changes(ders=ders)
    assert net.der_solar.tolist() == [True, False]
    p = np.array([[0.0, 0.4], [0.25, -1e-6]])
    sc = Scenario(net, np.ones(2), p).with_night_q(np.array([True, False]))
    limit = sc.qmax_mvar()
    assert limit[0, 0] == pytest.approx(0.5 / 0.9)  # the solar unit at night: S-limited "Q at night"
    assert limit[0, 1] == pytest.approx(0.4 * INVERTER_TAN_PHI_MAX)  # the wind unit keeps its day limit
    assert limit[1].tolist() == pytest.approx([0.25 * INVERTER_TAN_PHI_MAX, 1e-6 * INVERTER_TAN_PHI_MAX])
    assert qmax(net.der_kinds, p, net.der_rating_mw, net.der_s_mva).shape == (2, 2)
    for name in ("llma", "lfma", "acopf", "socp"):
        res = run_strategy(name, sc, 0.4)
        assert (np.abs(res.q_mvar) <= 0.6 * limit + 1e-9).all(), name  # the (1 − k) reserve
    with pytest.raises(InputError, match=r"must lie in \[−S̄, rating\]"):
        Scenario(net, np.ones(1), np.array([[0.0, -1.0]]))
    with pytest.raises(InputError, match=r"must lie in \[0, rating\]"):
        Scenario(load_network("paper33"), np.ones(1), np.array([[-0.1, 0, 0, 0, 0]]))
