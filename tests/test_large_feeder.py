"""The large radial feeders (`opfbench.cases.feeder`): the documented rule, power flow
against pandapower, batched vs Newton–Raphson, and LFMA on 96 snapshots. Default tests
use feeder1k (990 buses); feeder10k ones are slow-marked."""

import json

import numpy as np
import pytest

from opfbench.bench.pf_large import day96
from opfbench.cases import feeder, place_ders
from opfbench.cli import main
from opfbench.io import load_network
from opfbench.powerflow import bus_injections, solve_pf, solve_pf_batch
from opfbench.registry.catalog import run_strategy
from opfbench.strategies.paper import lfma_trace


def test_one_copy_is_case33bw_with_place_ders():
    one, base = feeder(1), load_network("case33bw")
    assert np.abs(one.ybus - base.ybus).max() == 0
    assert np.array_equal(one.load_p_mw, base.load_p_mw) and np.array_equal(one.bus_ids, base.bus_ids)
    placed = place_ders(base, "x")
    assert one.ders == placed.ders


def test_feeder1k_follows_the_rule():
    net, base = load_network("feeder1k"), load_network("case33bw")
    c = 30
    assert net.n_bus == 33 * c and net.n_branch == 33 * c - 1 and not net.meshed
    assert len(net.ders) == 5 * c and net.summary()["load_mw"] == pytest.approx(base.load_p_mw.sum())
    assert net.der_rating_mw.sum() == pytest.approx(0.8075 * base.load_p_mw.sum())
    # Copy k repeats copy 0's DER positions, 33 buses further on.
    assert np.array_equal(net.der_bus.reshape(c, 5) - net.der_bus[:5], np.repeat(33 * np.arange(c)[:, None], 5, 1))


def test_feeder1k_losses_and_voltages_stay_those_of_case33bw():
    """Each copy repeats case33bw's voltage drops at 1/c of its load, so vmin is case33bw's
    less the trunk's drop and losses case33bw's plus the trunk's (a few kW)."""
    net = load_network("feeder1k")
    r, base = solve_pf(net, bus_injections(net)), solve_pf(load_network("case33bw"), bus_injections(load_network("case33bw")))
    assert r.converged
    assert 0 < r.losses_kw - base.losses_kw < 10
    assert 0 < base.extreme_voltage("min")[0] - r.extreme_voltage("min")[0] < 0.005


def test_feeder1k_agrees_with_pandapower():
    from tests.support.pandapower_oracle import pandapower_pf

    net = load_network("feeder1k")
    rng = np.random.default_rng(2)
    p, q = rng.uniform(0, 1, len(net.ders)) * net.der_rating_mw, rng.uniform(-0.3, 0.3, len(net.ders)) * net.der_rating_mw
    ours = solve_pf(net, bus_injections(net, p, q, 1.2))
    vm, losses, _ = pandapower_pf(net, 1.2, p, q)
    assert ours.converged
    assert np.abs(ours.vm - vm).max() < 1e-6
    assert abs(ours.losses_kw - losses) < 1e-3


def test_feeder1k_batched_agrees_with_newton():
    day = day96("feeder1k")
    s = day.injections(np.zeros_like(day.der_p_mw))
    batch = solve_pf_batch(day.net, s)
    assert batch.converged.all()
    for k in (0, 30, 48, 70):
        single = solve_pf(day.net, s[k], tol=1e-10)  # tighter than default: the laterals' 30× impedances amplify mismatch
        assert np.abs(batch.v[k] - single.v).max() < 1e-8


def test_lfma_on_feeder1k_detects_every_upstream_line():
    day = day96("feeder1k")
    res = run_strategy("lfma", day, 0.4)
    assert (res.status == "ok").all()
    assert all(lst == [] for lst in res.extra["upstream_disagreements"])
    none = run_strategy("no-action", day, 0.4)
    assert (res.losses_kw <= none.losses_kw + 1e-6).all()
    trace = lfma_trace(day, 0.4)
    assert np.array_equal(trace.q_final, res.q_mvar)


def test_pf_command_on_feeder1k(capsys):
    assert main(["pf", "feeder1k", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["losses_kw"] == pytest.approx(
        solve_pf(
            load_network("feeder1k"), bus_injections(load_network("feeder1k"), 0.8 * load_network("feeder1k").der_rating_mw)
        ).losses_kw,
        abs=1e-6,
    )


@pytest.mark.slow
def test_feeder10k_power_flow_batch_and_lfma():
    day = day96("feeder10k")
    net = day.net
    assert net.n_bus == 9999 and len(net.ders) == 1515
    s = day.injections(np.zeros_like(day.der_p_mw))
    batch = solve_pf_batch(net, s)
    assert batch.converged.all()
    single = solve_pf(net, s[48], tol=1e-10)  # ~1e-11 p.u. is the rounding floor here
    assert single.converged and np.abs(batch.v[48] - single.v).max() < 1e-8
    res = run_strategy("lfma", day, 0.4)
    assert (res.status == "ok").all()
    assert all(lst == [] for lst in res.extra["upstream_disagreements"])
