"""The dense three-phase power flow's certificate (`powerflow.multiphase._certify`): the
mismatch is formed per snapshot on the nodes loads and DER touch (K), every other node's
is the network's solves' backward error (`_linear_error`), certified once. It must judge
as the mismatch formed at every node does: equal on K, the rest at round-off on every
snapshot, and a wrong impedance column at a node off K fails every snapshot."""

from __future__ import annotations

import dataclasses

import numpy as np

import opfbench.powerflow.multiphase as multiphase
from opfbench.io import load_case
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import MISMATCH_REL, branch_loads, certify, iterate_phase_flow


def _day(net: PhaseNetwork) -> tuple[np.ndarray, ...]:
    """Six snapshots: light to heavy load, full sun to none (PV at its rating × sun)."""
    mult = np.array([0.2, 0.5, 0.8, 1.0, 1.3, 1.6])[:, None]
    sun = np.array([1.0, 0.9, 0.6, 0.3, 0.1, 0.0])[:, None]
    p = sun * net.der_rating_mw[None, :]
    return mult * net.load_p_mw[None], mult * net.load_q_mvar[None], p, -0.3 * p


def _every_node(net: PhaseNetwork, v: np.ndarray, powers: tuple[np.ndarray, ...]) -> np.ndarray:
    """(S, n_node) the relative nodal mismatch at every node of voltages v (S, n_node)."""
    sys_ = multiphase._system(net)
    branch = multiphase._branch_powers(net, branch_loads(net, *powers[:2]), *powers[2:])
    given = sys_.injections(v.T[sys_.k], *branch)
    residual = net.ybus @ v.T - net.source_current[:, None]
    residual[sys_.k] -= given
    scale = abs(net.ybus) @ np.abs(v.T) + np.abs(net.source_current)[:, None]
    scale[sys_.k] += np.abs(given)
    return (np.abs(residual) / np.where(scale > 0, scale, 1.0)).T


def test_the_mismatch_on_k_judges_as_every_nodes():
    net = load_case("eulv").network
    assert isinstance(net, PhaseNetwork)
    sys_ = multiphase._system(net)
    assert sys_.z_nk is not None and len(sys_.k) < net.n_node / 10
    powers = _day(net)
    loads = branch_loads(net, *powers[:2])
    flow = certify(iterate_phase_flow(net, loads, *powers[2:]), loads, *powers[2:])
    assert flow.converged.all()
    every = _every_node(net, flow.v, powers)
    off_k = np.setdiff1d(np.arange(net.n_node), sys_.k)
    np.testing.assert_allclose(np.maximum(every[:, sys_.k].max(axis=1), sys_.linear_error), flow.mismatch, rtol=1e-6)
    assert every[:, off_k].max() < 1e3 * np.finfo(float).eps and sys_.linear_error < 1e3 * np.finfo(float).eps


def test_a_wrong_impedance_off_k_fails_every_snapshot():
    """Z_NK off by 1e-4 at one node no load or DER touches: the network's backward error
    says so, and no snapshot converges — as the mismatch formed at every node finds."""
    net = load_case("eulv").network
    assert isinstance(net, PhaseNetwork)
    sys_ = multiphase._system(net)
    assert sys_.z_nk is not None
    node = int(np.setdiff1d(np.arange(net.n_node), np.concatenate([sys_.k, net.source.nodes]))[len(sys_.k)])
    z_nk = sys_.z_nk.copy()
    z_nk[node] *= 1 + 1e-4
    wrong = dataclasses.replace(sys_, z_nk=z_nk, linear_error=multiphase._linear_error(net, sys_.v_source, z_nk, sys_.k))
    powers = _day(net)
    loads = branch_loads(net, *powers[:2])
    state = iterate_phase_flow(net, loads, *powers[2:])
    good = multiphase._certify(state, sys_, multiphase._branch_powers(net, loads, *powers[2:]))
    bad = multiphase._certify(state, wrong, multiphase._branch_powers(net, loads, *powers[2:]))
    assert good.converged.all() and not bad.converged.any()
    assert (bad.mismatch > MISMATCH_REL).all()
    assert (_every_node(net, bad.v, powers).max(axis=1) > MISMATCH_REL).all()
