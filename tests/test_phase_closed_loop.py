"""The three-phase closed loop on iterates (`strategies.grids.PhaseGrid`): each step is a
`PhaseIterate` (the currents at the nodes loads and DER touch, every node's voltage formed
only where the settling check asks), the voltage check decided by a bound where it is far
below the tolerance, and only each snapshot's last step certified. It must give what the
loop gives when every step is a certified flow on every node (`CertifiedPhaseGrid`, the
grid of feeders with `?taps=control`) — the same setpoints, statuses, flow counts and
figures — on the dense and the sparse iteration alike."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import opfbench.powerflow.multiphase as multiphase
import opfbench.strategies.rule_engine as rule_engine
from opfbench.io import load_case
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import branch_loads, iterate_phase_flow, voltages_within
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario
from opfbench.strategies.grids import CertifiedPhaseGrid, grid_of

IEEE13_DER = "?der=675:inverter:0.5,671:inverter:0.4,611.3:inverter:0.05,652.1:inverter:0.05"


def _scenario(net: PhaseNetwork) -> Scenario:
    """Five snapshots from light load and full sun to heavy load and little sun."""
    load = np.array([0.3, 0.6, 1.0, 1.3, 0.5])
    sun = np.array([0.95, 0.8, 0.5, 0.1, 0.0])
    return Scenario(net, load, sun[:, None] * net.der_rating_mw[None, :], None)


def _sparse(net: PhaseNetwork, monkeypatch) -> PhaseNetwork:
    """The same feeder through the sparse iteration (a fresh object: its own system)."""
    monkeypatch.setattr(multiphase, "DENSE_MAX_NODES", 0)
    return dataclasses.replace(net)


@pytest.mark.parametrize("spec", ["eulv", f"ieee13{IEEE13_DER}"])
@pytest.mark.parametrize("iteration", ["dense", "sparse"])
@pytest.mark.parametrize("strategy", ["volt-var:tol_q_mvar=1e-10", "volt-var+volt-watt"])
def test_closed_loop_on_iterates_equals_certified_steps(spec, iteration, strategy, monkeypatch):
    net = load_case(spec).network
    assert isinstance(net, PhaseNetwork)
    if iteration == "sparse":
        net = _sparse(net, monkeypatch)
    assert (multiphase._system(net).z_nk is None) == (iteration == "sparse")
    scenario = _scenario(net)
    ours = run_strategy(strategy, scenario, 0.0)
    monkeypatch.setattr(rule_engine, "grid_of", CertifiedPhaseGrid)
    certified = run_strategy(strategy, scenario, 0.0)
    assert list(ours.status) == list(certified.status) and (ours.status == "ok").sum() >= 3
    np.testing.assert_array_equal(ours.power_flows, certified.power_flows)
    np.testing.assert_allclose(ours.q_mvar, certified.q_mvar, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.losses_kw, certified.losses_kw, rtol=1e-10)
    np.testing.assert_allclose(ours.vm, certified.vm, rtol=0, atol=1e-12)
    assert np.abs(ours.q_mvar).max() > 0  # the rule acts


@pytest.mark.parametrize("iteration", ["dense", "sparse"])
def test_voltages_within_decides_as_the_exact_change(iteration, monkeypatch):
    """The settling check on two iterates' states: the same verdict as the exact largest
    change of a node's |V| (p.u.), just below and above it (the exact test decides) and far
    above it (the bound decides)."""
    net = load_case(f"ieee13{IEEE13_DER}").network
    assert isinstance(net, PhaseNetwork)
    if iteration == "sparse":
        net = _sparse(net, monkeypatch)
    lp, lq = net.load_p_mw[None].repeat(3, 0), net.load_q_mvar[None].repeat(3, 0)
    p = 0.8 * net.der_rating_mw[None].repeat(3, 0)
    q = np.array([0.0, 1e-6, 1e-2])[:, None] * np.ones(len(net.ders))
    loads = branch_loads(net, lp, lq)
    before = iterate_phase_flow(net, loads, p, np.zeros_like(q))
    after = iterate_phase_flow(net, loads, p, q, start=before)
    base = net.node_base_v
    change = np.abs(np.abs(after.v) / base - np.abs(before.v) / base).max(axis=1)
    assert change[0] < 1e-10 < change[1] < 1e-5 < change[2]  # no step (the warm start re-iterated), a small one, a large one
    for factor in (1 - 1e-6, 1 + 1e-6, 1e3):
        tol = factor * change[1]
        np.testing.assert_array_equal(voltages_within(after, before, tol), change <= tol)


def test_a_feeder_under_tap_control_steps_on_certified_flows():
    """With `?taps=control` the regulators move inside every solve, so the loop steps on
    certified flows (`CertifiedPhaseGrid`), the taps settled per snapshot; the iterate has
    no taps to move and refuses such a feeder."""
    net = load_case("ieee13?der=675:inverter:0.5,671:inverter:0.4&taps=control").network
    assert isinstance(net, PhaseNetwork) and net.tap_control and net.regulators
    scenario = Scenario(net, np.array([0.4, 1.0]), np.array([0.9, 0.2])[:, None] * net.der_rating_mw[None, :], None)
    assert isinstance(grid_of(scenario), CertifiedPhaseGrid)
    res = run_strategy("volt-var", scenario, 0.0)
    assert list(res.status) == ["ok", "ok"] and res.power_flows[0] > 2 and np.abs(res.q_mvar[0]).max() > 0
    with pytest.raises(ValueError, match="tap control"):
        iterate_phase_flow(net, branch_loads(net, net.load_p_mw[None], net.load_q_mvar[None]))
