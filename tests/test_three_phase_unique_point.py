"""The certificate of a step without a decision (`formulations.unique_point`): eulv's night
on its houses' own load shapes (PV at 0 with no Q: every usable |Q| is 0). The contraction
factor bounds how the network's fixed-point map moves two voltage states (checked against
the map itself at the power flow's point and beside it); it refuses a loading where it
cannot prove one solution; and a run's night steps are certified by it, their bound the
power flow's losses, with no SDP solved."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from opfbench.api import load_case
from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import case_with_pv
from opfbench.data.profiles import paper_day
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.three_phase import BAND_TOL, UNIQUE
from opfbench.formulations.unique_point import CONTRACTION_MAX, contraction, unique_point
from opfbench.multiphase import GROUND
from opfbench.powerflow.multiphase import _branch_powers, _system, branch_loads, solve_phase_flow
from opfbench.result import CERTIFIED_BY_UNIQUE, OK
from opfbench.scenario import Scenario

NIGHT = [0, 90, 240]  # 00:00, 01:30, 04:00 UTC of the paper day (no sun)


@pytest.fixture(scope="module")
def night():
    case = load_case("eulv")
    net = case.network
    index = paper_day().index[NIGHT]
    lp, lq, _ = case.series.rows(index)
    dp = np.zeros((len(NIGHT), len(net.ders)))
    return net, lp, lq, dp, index


def _map(net, v: np.ndarray, powers) -> np.ndarray:
    """The network's fixed-point map T(V) = Y⁻¹·(I_source + I_branches(V)) at node voltages
    v (n_node, S), the branches' currents as the power flow forms them."""
    sys_ = _system(net)
    rhs = np.repeat(np.asarray(net.source_current, dtype=complex)[:, None], v.shape[1], axis=1)
    rhs[sys_.k] += sys_.injections(np.ascontiguousarray(v[sys_.k]), *powers)
    return sla.splu(net.ybus.tocsc()).solve(rhs)


def test_the_contraction_bounds_the_networks_map_at_night(night):
    """At three night steps: the power flow's point is the map's fixed point (the equations
    the factor is derived from are the power flow's), the factor is below CONTRACTION_MAX,
    and 20 random states within 0.5 % of the point (inside the region) move under the map
    by at most the factor times their distance, on the nodes the branches touch."""
    net, lp, lq, dp, _ = night
    flow = solve_phase_flow(net, lp, lq, dp, tol=1e-12, max_iter=500)
    assert flow.converged.all()
    unique, factor = unique_point(net, flow, lp, lq, dp, np.zeros_like(dp), BAND_TOL)
    assert unique.all() and (factor < CONTRACTION_MAX).all() and (factor > 0).all(), factor
    powers = _branch_powers(net, branch_loads(net, lp, lq), dp, None)
    v = flow.v.T
    base = net.node_base_v[:, None]
    assert (np.abs(_map(net, v, powers) - v) / base).max() < 1e-7  # p.u.: the power flow's own accuracy
    ends = np.concatenate([net.load_branches.a, net.load_branches.b, net.der_branches.a, net.der_branches.b])
    nodes = np.unique(ends[ends != GROUND])
    rng = np.random.default_rng(7)
    worst = np.zeros(len(NIGHT))
    for _ in range(20):
        moved = v.copy()
        delta = rng.normal(size=(len(nodes), len(NIGHT))) + 1j * rng.normal(size=(len(nodes), len(NIGHT)))
        moved[nodes] += 0.005 * base[nodes] * delta / np.abs(delta)
        change = np.abs(_map(net, moved, powers) - _map(net, v, powers))[nodes] / base[nodes]
        worst = np.maximum(worst, change.max(axis=0) / 0.005)
    assert (worst <= factor).all(), (worst, factor)
    assert (worst > 1e-3 * factor).all()  # the map does move them: the comparison is not empty


def test_a_loading_it_cannot_prove_is_refused(night):
    """A hundred times the night's load: the factor passes CONTRACTION_MAX (no certificate),
    whatever the power flow finds; a load with no row bounding its voltage from below (the
    band removed from the region by an infinite tolerance) gets none either."""
    net, lp, lq, dp, _ = night
    heavy = contraction(net, 100 * lp, 100 * lq, dp, dp, BAND_TOL)
    assert (heavy >= CONTRACTION_MAX).all(), heavy
    assert np.isinf(contraction(net, lp, lq, dp, dp, np.inf)).all()


def test_a_runs_night_steps_are_certified_without_the_sdp(night):
    """`run_phase` bounded on three night steps: every step certified by `unique`, its lower
    bound the reported losses, status UNIQUE, no SDP time."""
    net, lp, lq, dp, _ = night
    scenario = Scenario(net, None, dp, load_p_mw=lp, load_q_mvar=lq)
    res = run_acopf(scenario, 0.0, solver="auto")
    assert (res.status == OK).all()
    assert (res.solver.certified_by == CERTIFIED_BY_UNIQUE).all()
    assert np.allclose(res.lower_bound_kw, res.losses_kw, rtol=0, atol=0)
    assert (res.extra["sdp_status"] == UNIQUE).all() and (res.extra["sdp_ms"] == 0).all()
    assert (res.extra["contraction"] < CONTRACTION_MAX).all()


def test_a_regulated_feeder_with_delta_loads_at_k_1(tmp_path):
    """ieee13 under tap control (`?taps=control`: delta and constant-|I| loads, regulators)
    at k = 1 — no decision at any step: each step is checked on the feeder at the taps its
    power flow settles (`sole_points`), the factor finite; at 40 % load certified, the
    bound the reported losses; at full load the factor passes CONTRACTION_MAX: not
    certified by it (the step goes to the relaxation's sample instead)."""
    with opendss_copy("ieee13") as master:
        case = case_with_pv(tmp_path, master, "ieee13", taps="control")
    net = dataclasses.replace(case.network, band=(0.9, 1.1))
    lp, lq, dp, _ = case.stored
    mult = np.array([[0.4], [1.0]])
    scenario = Scenario(net, None, np.tile(dp * 0.5, (2, 1)), load_p_mw=lp * mult, load_q_mvar=lq * mult)
    res = run_acopf(scenario, 1.0, solver="auto")
    factor = res.extra["contraction"]
    assert np.isfinite(factor).all() and (factor > 0).all(), factor
    unique = res.solver.certified_by == CERTIFIED_BY_UNIQUE
    assert unique.tolist() == [True, False]  # at full load the factor passes CONTRACTION_MAX: refused
    assert factor[1] >= CONTRACTION_MAX and res.status[1] == OK
    assert (res.lower_bound_kw[unique] == res.losses_kw[unique]).all() and res.extra["sdp_status"][1] != UNIQUE
