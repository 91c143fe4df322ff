"""The three-phase AC OPF (`formulations.models.ac_three_phase` through
`formulations.three_phase.optimum`): its optimum confirmed by OpenDSS (the Q setpoints as
fixed kvar on the same PVSystems, the regulator taps held), never above no action where
no action meets the band, proven infeasible where nothing can reach the band, and its
input checked before any work. The feeder: `ieee123` with single-phase PV on every second
load (`opfbench.cases.opendss_pv`)."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import case_with_pv, with_pv
from opfbench.errors import InputError
from opfbench.formulations.frontier import COVER_PU, frontier, widened
from opfbench.formulations.model import built, model_for
from opfbench.formulations.models.ac_three_phase import OPTIONS
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.solvers.ipopt_adapter import IpoptNlp
from opfbench.formulations.three_phase import BAND_TOL, CERTIFY_RTOL, NO_Q_TO_GIVE, optimum, q_limits
from opfbench.multiphase import PhaseNetwork
from opfbench.network import V_LIMIT_MAX_PU
from opfbench.powerflow.multiphase import solve_phase_flow
from opfbench.registry.catalog import run_strategy
from opfbench.result import INFEASIBLE, OK
from opfbench.scenario import Scenario
from tests.support.opendss_feeders import held_taps, solve

# (load multiplier, PV irradiance): noon with the band binding, afternoon, evening peak
SNAPSHOTS = ((0.9, 1.0), (1.0, 0.6), (1.1, 0.3))
STRICT = {"ipopt.tol": 1e-10, "ipopt.acceptable_iter": 15, "ipopt.acceptable_obj_change_tol": 1e20}


def _feeder(tmp, name: str, **placement):
    """The shipped feeder with PV (`opendss_pv`), and a master file of the same feeder and
    PV that outlives the temporary copy (OpenDSS's oracle compiles it)."""
    with opendss_copy(name) as master:
        case = case_with_pv(tmp, master, name, **placement)
        shutil.copytree(master.parent.parent, tmp / "feeder")
        file = with_pv(tmp, tmp / "feeder" / master.parent.name / master.name, case.network, **placement)
    assert isinstance(case.network, PhaseNetwork)
    return case, file


@pytest.fixture(scope="module")
def ieee123_pv(tmp_path_factory):
    case, file = _feeder(tmp_path_factory.mktemp("ieee123_pv"), "ieee123")
    assert len(case.network.ders) == 46
    return case, file


def _snapshots(case, snapshots):
    lp, lq, dp, _ = case.stored
    mult = np.array([s[0] for s in snapshots])[:, None]
    sun = np.array([s[1] for s in snapshots])[:, None]
    return lp * mult, lq * mult, dp * sun


def test_the_three_phase_model_serves_unbalanced_feeders_by_its_declaration(ieee123_pv):
    case, _ = ieee123_pv
    assert model_for("exact", case.network).name == "ac3"


def _confirmed_by_opendss(case, file, snapshots):
    """The OPF's Q as fixed kvar on the same PVSystems in OpenDSS (loads by loadmult, PV by
    irradiance, taps held): OpenDSS's losses within 1e-6 relative of the OPF's and every
    monitored voltage within the band. Returns the OPF's result."""
    net = case.network
    lp, lq, dp = _snapshots(case, snapshots)
    result = optimum(net, lp, lq, dp, 0.0)
    assert (result.status == OK).all(), result.status
    a, b, base, _ = net.monitored
    lo, hi = net.band
    for i, (mult, sun) in enumerate(snapshots):
        kvar = [
            f"{name}.irradiance={sun!r} kvar={float(q) * 1e3!r}" for name, q in zip(net.der_names, result.q_mvar[i], strict=True)
        ]
        theirs = solve(file, f"set loadmult={mult!r}", *held_taps(net), *kvar, controls=False)
        assert theirs.converged and theirs.node_names == list(net.node_names)
        assert theirs.losses_kw == pytest.approx(result.losses_kw[i], rel=1e-6)
        vx = np.append(theirs.v, 0.0)
        vm = np.abs(vx[a] - vx[b]) / base
        assert lo - BAND_TOL <= vm.min() and vm.max() <= hi + BAND_TOL
    assert np.abs(result.q_mvar).max() > 0.1 * max(d.s_rated_mva for d in net.ders)  # the DER do act
    return result


def test_opendss_confirms_the_optimum(ieee123_pv):
    result = _confirmed_by_opendss(*ieee123_pv, SNAPSHOTS)
    assert result.vmax[0] == pytest.approx(ieee123_pv[0].network.band[1], abs=1e-6)  # the band binds at noon


@pytest.mark.slow
def test_opendss_confirms_the_optimum_on_eulv(tmp_path):
    """The European LV feeder (2721 nodes) with 4-kW PV on every second house."""
    _confirmed_by_opendss(*_feeder(tmp_path, "eulv", kw=4.0), SNAPSHOTS)


def test_the_optimum_is_not_above_a_better_point_a_stricter_solve_confirms(ieee123_pv):
    """IPOPT's tolerance is on the scaled problem, where the stiff source's admittance
    scales the objective (kW) by ~2e-4 (`ac_three_phase.OPTIONS`): at IPOPT's usual 1e-8
    the accepted optimum sat 1e-5–4e-5 of the losses above points the power flow confirms.
    The same NLP solved again from the optimum's point to tol 1e-10 with no early stop
    (15 iterations at the acceptable level: slower): the power flow at its setpoints meets
    the band, and the optimum's losses are not above it by more than a certificate's
    tolerance (CERTIFY_RTOL; at IPOPT's usual 1e-8 the noon snapshot sat 3.2e-5 above)."""
    case, _ = ieee123_pv
    net = case.network
    lp, lq, dp = _snapshots(case, SNAPSHOTS)
    result = optimum(net, lp, lq, dp, 0.0)
    assert (result.status == OK).all(), result.status
    exact = built(model_for("exact", net), net, True)
    strict = IpoptNlp("ac3_strict", exact.nlp.nlp, exact.nlp.lbg, exact.nlp.ubg, exact.nlp.setpoints, OPTIONS | STRICT)
    limit = q_limits(net, dp, 0.0)
    big = np.full(exact.initial(result.flow.v[0]).size - len(net.ders), np.inf)
    lo, hi = net.band
    compared = 0
    for i in range(len(SNAPSHOTS)):
        x0 = exact.initial(result.flow.v[i], q_mvar=result.q_mvar[i])
        answer = strict.solve(
            np.concatenate([lp[i], lq[i], dp[i]]), np.concatenate([-limit[i], -big]), np.concatenate([limit[i], big]), x0, None
        )
        assert answer.success, answer.status
        there = solve_phase_flow(net, lp[i : i + 1], lq[i : i + 1], dp[i : i + 1], answer.q_pu[None])
        if there.converged[0] and lo - BAND_TOL <= there.vm[0].min() and there.vm[0].max() <= hi + BAND_TOL:
            compared += 1
            assert result.losses_kw[i] <= there.losses_kw[0] * (1 + CERTIFY_RTOL), (i, result.losses_kw[i], there.losses_kw[0])
    assert compared == len(SNAPSHOTS)


def test_the_optimum_is_never_above_no_action_where_no_action_meets_the_band(ieee123_pv):
    case, _ = ieee123_pv
    net = case.network
    snapshots = [(m, s) for m in (0.8, 1.1) for s in (0.0, 0.4, 0.9)]
    lp, lq, dp = _snapshots(case, snapshots)
    result = optimum(net, lp, lq, dp, 0.4)
    none = solve_phase_flow(net, lp, lq, dp)
    lo, hi = net.band
    in_band = (none.vm.min(axis=1) >= lo) & (none.vm.max(axis=1) <= hi)
    assert in_band.sum() >= 2
    assert not np.isnan(result.losses_kw[in_band]).any()
    assert (result.losses_kw[in_band] <= none.losses_kw[in_band] * (1 + 1e-9)).all()
    assert (result.losses_kw[in_band] < none.losses_kw[in_band] - 0.1)[dp[in_band].sum(axis=1) > 0].any()


def test_the_frontier_widens_the_band_of_one_compiled_model(ieee123_pv):
    """The frontier on ieee123 at noon (the band binds) and in the evening (it does not):
    non-increasing in ε, each point within its own widened band, the widened feeders
    derived from this one (`origin`: one compiled model serves every ε), solved again only
    where the band binds; its points carry no SDP bound."""
    case, _ = ieee123_pv
    net = case.network
    lp, lq, dp = _snapshots(case, SNAPSHOTS)
    scenario = Scenario.from_series(net, lp, lq, dp)
    front = frontier(scenario, 0.0)
    assert not np.isnan(front.cost_kw).any() and (np.diff(front.cost_kw, axis=1) <= 1e-6).all()
    assert (front.excursion_pu <= front.eps + COVER_PU).all()
    assert front.cost_kw[0, -1] < front.cost_kw[0, 0] - 0.1  # noon: a wider band saves losses
    assert front.solved[0, [0, -1]].all() and not front.solved[2, 1:].any()  # evening: solved once
    wide = widened(net, 0.02)
    assert wide.origin is net and wide.band == (net.band[0] - 0.02, net.band[1] + 0.02) and wide.ybus is net.ybus
    assert widened(net, math.inf).band == (0.0, V_LIMIT_MAX_PU)
    assert front.excursion_pu[0, 1] > 0  # the optimum at ε = 0.0025 uses its widening
    assert np.isnan(front.bound_kw).all()  # no SDP a frontier point: seconds a step (eulv: a minute)


def test_rules_that_curtail_lie_on_or_above_the_three_phase_frontier_that_may_curtail(ieee123_pv):
    """ieee123 in full sun with its upper limit lowered to 1.04 p.u.: the optimum that may
    curtail (losses + curtailed power, `acopf:curtail=true`) is a frontier at or below the
    plain one at every ε, and Volt-Watt (curtailing from 1.0 p.u.) never lies below it at its
    own compliance; the optimum curtails where nothing else holds the band."""
    case, _ = ieee123_pv
    net = case.network.with_band(case.network.band[0], 1.04)
    lp, lq, dp = _snapshots(case, [(0.9, 1.0), (1.0, 0.9)])
    scenario = Scenario.from_series(net, lp, lq, dp)
    plain, cutting = frontier(scenario, 0.0), frontier(scenario, 0.0, curtail=True)
    assert cutting.curtail and not np.isnan(cutting.cost_kw[:, 0]).any()
    both = ~np.isnan(plain.cost_kw) & ~np.isnan(cutting.cost_kw)  # IPOPT may fail at an ε (no point there, counted)
    assert both.mean() > 0.8
    assert (cutting.cost_kw[both] <= plain.cost_kw[both] * (1 + 1e-4)).all()  # IPOPT's optimality on ac3: ~3e-5 relative
    res = run_strategy("volt-watt:v=1/1.04,p=1/0", scenario, 0.0)
    assert res.curtailed_kw.sum() > 1.0
    cost, _, _ = cutting.at(res.voltage_violation())
    assert (res.losses_kw + res.curtailed_kw >= cost - 1e-4).all()
    optimum_cut = run_acopf(scenario, 0.0, curtail=True)
    assert (optimum_cut.status == OK).all() and optimum_cut.vmax.max() <= 1.04 + BAND_TOL
    np.testing.assert_allclose(optimum_cut.losses_kw + optimum_cut.curtailed_kw, cutting.cost_kw[:, 0], rtol=1e-9)


def test_no_q_to_give_and_the_band_left_is_infeasible_with_no_figure(ieee123_pv):
    """At night (PV at 0: an inverter has no Q) and light load the held taps leave the band:
    the power flow's point, the only candidate found, is out of it, so the step is
    infeasible (a local verdict, not called proven) — and gives no losses."""
    case, _ = ieee123_pv
    lp, lq, dp = _snapshots(case, [(0.3, 0.0), (1.0, 0.0)])
    result = optimum(case.network, lp, lq, dp, 0.0)
    assert result.status[0] == INFEASIBLE and result.solver_status[0] == NO_Q_TO_GIVE
    assert np.isnan(result.losses_kw[0]) and np.isnan(result.objective_kw[0])
    assert result.status[1] == OK and result.losses_kw[1] == pytest.approx(
        solve_phase_flow(case.network, lp[1:], lq[1:], dp[1:]).losses_kw[0]
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [("k", "reserve coefficient"), ("nan", "load P contains NaN"), ("shape", "DER P must have shape")],
)
def test_bad_input_is_one_message_before_any_work(ieee123_pv, change, message):
    case, _ = ieee123_pv
    lp, lq, dp = _snapshots(case, SNAPSHOTS[:1])
    k = 1.5 if change == "k" else 0.0
    if change == "nan":
        lp = lp.copy()
        lp[0, 3] = np.nan
    if change == "shape":
        dp = dp[:, :-1]
    with pytest.raises(InputError, match=message):
        optimum(case.network, lp, lq, dp, k)
