"""The SDP relaxation of the three-phase OPF (`formulations.models.sdp_three_phase` through
`formulations.three_phase.bound`): at rank one it is the exact model (an operating point
lifted into it meets every constraint, with its losses as the objective), so its optimum
is a lower bound — never above the AC optimum; its rank-one check tells a lifted point
from a mixture of two; meshed feeders and bad input are refused before any work.

The feeder: `ieee13` with PV on every second load, the band widened to 0.90–1.10 p.u.
(with the taps held the file settles, its regulator output is above 1.05 p.u. and the
0.95–1.05 band is infeasible)."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import case_with_pv
from opfbench.data.profiles import paper_day
from opfbench.errors import InputError, NetworkError
from opfbench.formulations import three_phase
from opfbench.formulations.model import model_for
from opfbench.formulations.models.sdp_three_phase import RANK_RATIO, ThreePhaseSdp
from opfbench.formulations.three_phase import (
    BOUND_SAMPLE,
    CERTIFY_RTOL,
    NO_RELAXATION,
    NOT_SAMPLED,
    PhaseBound,
    bound,
    bound_sample,
    certify,
    optimum,
    q_limits,
    step_bounds,
)
from opfbench.multiphase import Element
from opfbench.powerflow.multiphase import solve_phase_flow
from opfbench.result import CERTIFIED_BY_SDP

SOLVER_RTOL = 1e-5
"""How far Clarabel's optimal value may sit from the exact one at eulv's night step
(relative; over the paper day's night steps it ranged from −1.2e-5 to +3e-6)."""
# (load multiplier, PV irradiance): noon, afternoon, evening peak, night
SNAPSHOTS = ((0.6, 1.0), (0.9, 0.6), (1.1, 0.3), (1.0, 0.0))


@pytest.fixture(scope="module")
def ieee13(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ieee13_pv")
    with opendss_copy("ieee13") as master:
        case = case_with_pv(tmp, master, "ieee13")
    shutil.rmtree(tmp, ignore_errors=True)
    net = dataclasses.replace(case.network, band=(0.9, 1.1))
    lp, lq, dp, _ = case.stored
    mult = np.array([s[0] for s in SNAPSHOTS])[:, None]
    sun = np.array([s[1] for s in SNAPSHOTS])[:, None]
    return net, lp * mult, lq * mult, dp * sun


@pytest.fixture(scope="module")
def ieee13_held(ieee13):
    """The same feeder at its own band (0.95–1.05 p.u.)."""
    net, lp, lq, dp = ieee13
    return dataclasses.replace(net, band=(0.95, 1.05)), lp, lq, dp


@pytest.fixture(scope="module")
def model(ieee13):
    return ThreePhaseSdp(ieee13[0])


def _meshed(net):
    """`net` with a three-phase line closing a loop between buses 675 and 680."""
    line = next(e for e in net.elements if e.kind == "line" and e.nodes.shape == (2, 3))
    far = [i for i, name in enumerate(net.bus_names) if name in ("675", "680")]
    nodes = np.array([[int(np.flatnonzero((net.node_bus == b) & (net.node_phase == p))[0]) for p in (1, 2, 3)] for b in far])
    loop = Element("Line.loop", "line", tuple(far), nodes, line.yprim)
    meshed = dataclasses.replace(net, elements=(*net.elements, loop))
    assert meshed.meshed
    return meshed


def test_the_relaxation_serves_radial_feeders_and_refuses_meshed_ones(ieee13):
    net = ieee13[0]
    assert model_for("relaxation", net).name == "sdp3"
    meshed = _meshed(net)
    with pytest.raises(NetworkError, match="no relaxation formulation model serves unbalanced-meshed"):
        bound(meshed, *ieee13[1:])
    with pytest.raises(NetworkError, match="needs a radial feeder; this one is meshed"):
        ThreePhaseSdp(meshed)


def test_an_operating_point_lifted_meets_every_constraint_with_its_losses_as_objective(ieee13, model):
    """The power flow's no-action point, lifted (rank one), is feasible in the relaxation and
    its objective is the power flow's losses: the relaxation contains the exact model's
    feasible set with the same objective — the optimum below any AC point."""
    net, lp, lq, dp = ieee13
    i = 1
    flow = solve_phase_flow(net, lp[i : i + 1], lq[i : i + 1], dp[i : i + 1], tol=1e-13, max_iter=500)
    assert flow.converged[0]
    assert net.band[0] <= flow.vm[0].min() and flow.vm[0].max() <= net.band[1]
    model.lift(flow.v[0], lp[i], lq[i], dp[i], q_limits(net, dp[i : i + 1], 0.0)[0], np.zeros(len(net.ders)))
    assert model._flows is not None  # ieee13's switch is an ideal branch
    # to 1e-7 p.u.: the switch 671–692 is ideal in the relaxation, and the power flow's
    # voltage drop across its 1e-7 Ω is about 1e-8 p.u.
    bad = [(str(c)[:80], float(np.max(c.violation()))) for c in model.problem.constraints if np.max(c.violation()) >= 1e-7]
    assert not bad
    assert model.problem.objective.value == pytest.approx(flow.losses_kw[0], rel=1e-6)
    assert model.rank_ratios().max() < 1e-9  # a lifted point is rank one


def test_the_rank_one_check_tells_a_mixture_of_two_points(ieee13, model):
    net, lp, lq, dp = ieee13
    flows = solve_phase_flow(net, lp[:2], lq[:2], dp[:2], tol=1e-13, max_iter=500)
    xs = []
    for i in range(2):
        model.lift(flows.v[i], lp[i], lq[i], dp[i], q_limits(net, dp[i : i + 1], 0.0)[0], np.zeros(len(net.ders)))
        xs.append(model._x.value.copy())
    assert not np.allclose(xs[0], xs[1])
    model._x.value = xs[0]
    assert model.rank_ratios().max() <= RANK_RATIO
    model._x.value = (xs[0] + xs[1]) / 2
    assert model.rank_ratios().max() > RANK_RATIO


def test_the_relaxation_proves_ieee13_infeasible_with_its_taps_held(ieee13_held):
    """At the file's band (0.95–1.05) and held taps the regulator's output is above the band:
    Clarabel certifies the relaxation infeasible — so the exact problem is — and no step
    gets a bound, a gap or a certificate; the AC OPF finds no optimum either."""
    net, lp, lq, dp = ieee13_held
    relaxed = bound(net, lp[1:3], lq[1:3], dp[1:3], 0.0)
    assert relaxed.infeasible.all() and (relaxed.status == "infeasible").all()
    assert np.isnan(relaxed.bound_kw).all() and not relaxed.rank_one.any()
    opt = optimum(net, lp[1:3], lq[1:3], dp[1:3], 0.0)
    assert np.isnan(opt.losses_kw).all()
    certified, gap = certify(opt, relaxed)
    assert not certified.any() and np.isnan(gap).all()


def test_a_run_bounds_a_stated_sample_and_certifies_only_within_the_tolerance(ieee13, monkeypatch):
    """`run_phase`'s side (`step_bounds`): the relaxation on `bound_sample`'s steps only (the
    others `NOT_SAMPLED`, no bound, never certified); a step certified exactly where its
    point meets the band and its losses are within CERTIFY_RTOL of the bound, the relative
    gap recorded otherwise; a meshed feeder: no bound, said so. The bound here is a stand-in
    that returns chosen fractions of the AC optimum (the relaxation's own validity:
    `test_the_bound_is_never_above_the_ac_optimum`)."""
    assert bound_sample(BOUND_SAMPLE).tolist() == list(range(BOUND_SAMPLE))
    day = bound_sample(1440)
    assert len(day) == BOUND_SAMPLE and day[0] == 0 and day[-1] == 1439 and (np.diff(day) > 0).all()
    net, lp, lq, dp = ieee13
    opt = optimum(net, lp, lq, dp, 0.0)
    feasible = np.isfinite(opt.losses_kw)
    assert feasible.all(), opt.status
    factor = np.array([1 - 0.5 * CERTIFY_RTOL, 1.0, 1.0, 1 - 1e-4])
    attained = np.ones(4)  # the relaxation's own point's losses ÷ its value
    asked = []

    def stand_in(net_, load_p, load_q, der_p, k, *, q_limit_mvar):
        rows = [int(np.flatnonzero((lp == row).all(axis=1))[0]) for row in load_p]
        asked.append(rows)
        m = len(rows)
        status = np.full(m, "optimal", dtype=object)
        value = opt.losses_kw[rows] * factor[rows]
        return PhaseBound(
            value, np.zeros(m), np.ones(m, bool), np.zeros(m, bool), status, np.ones(m), value * attained[rows], 1.0
        )

    monkeypatch.setattr(three_phase, "bound", stand_in)
    monkeypatch.setattr(three_phase, "BOUND_SAMPLE", 2)
    limit = q_limits(net, dp, 0.0)
    by, rec = step_bounds(net, lp, lq, dp, limit, 0.0, opt, feasible)
    assert asked == [[0, 3]]  # the first and the last of four steps
    assert by.tolist() == [CERTIFIED_BY_SDP, "", "", ""]  # labels: who certified
    assert rec["sdp_status"].tolist() == ["optimal", NOT_SAMPLED, NOT_SAMPLED, "optimal"]
    np.testing.assert_allclose(rec["optimality_gap"][[0, 3]], [0.5 * CERTIFY_RTOL, 1e-4], rtol=1e-6)
    assert np.isnan(rec["relaxation_bound_kw"][[1, 2]]).all() and np.isnan(rec["optimality_gap"][[1, 2]]).all()
    # a value its own point does not attain (an inaccurate solve) certifies nothing, even within the gap
    attained[0] = 1 - 1e-5
    by, rec = step_bounds(net, lp, lq, dp, limit, 0.0, opt, feasible)
    assert not by.any() and rec["sdp_point_kw"][0] == pytest.approx(rec["relaxation_bound_kw"][0] * (1 - 1e-5))
    attained[0] = 1.0
    # a step whose reported point leaves the band is not certified, and has no gap
    by, rec = step_bounds(net, lp, lq, dp, limit, 0.0, opt, np.array([False, True, True, True]))
    assert not by.any() and np.isnan(rec["optimality_gap"][0]) and rec["relaxation_bound_kw"][0] > 0
    asked.clear()
    by, rec = step_bounds(_meshed(net), lp, lq, dp, limit, 0.0, opt, feasible)
    assert not asked and not by.any() and (rec["sdp_status"] == NO_RELAXATION).all()


@pytest.mark.slow
def test_the_bound_is_never_above_the_ac_optimum(tmp_path):
    """ieee123 with PV on every second load at noon (the band binding), afternoon and evening
    peak: where the relaxation solves, its bound is at most the AC optimum, and a step is
    certified exactly when the two agree within CERTIFY_RTOL."""
    with opendss_copy("ieee123") as master:
        case = case_with_pv(tmp_path, master, "ieee123")
    lp, lq, dp, _ = case.stored
    mult, sun = np.array([[0.9], [1.0], [1.1]]), np.array([[1.0], [0.6], [0.3]])
    lp, lq, dp = lp * mult, lq * mult, dp * sun
    net = case.network
    opt = optimum(net, lp, lq, dp, 0.0)
    relaxed = bound(net, lp, lq, dp, 0.0)
    both = np.isfinite(opt.losses_kw) & np.isfinite(relaxed.bound_kw)
    assert both.sum() >= 2, (opt.status, relaxed.status)
    assert (relaxed.bound_kw[both] <= opt.losses_kw[both] * (1 + CERTIFY_RTOL)).all()
    assert (relaxed.bound_kw[both] > 0.9 * opt.losses_kw[both]).all()
    certified, gap = certify(opt, relaxed)
    assert (certified == (np.abs(gap) <= CERTIFY_RTOL)).all() and not certified[~both].any()
    assert relaxed.compile_ms > 0 and (relaxed.solve_ms > 0).all()
    # the AC optimum lifted (rank one): feasible in the relaxation, its objective the power
    # flow's losses less the ideal switches' (below 2e-5 of them) — the same function
    model = ThreePhaseSdp(net)
    limit = q_limits(net, dp, 0.0)
    for i in np.flatnonzero(np.isfinite(opt.objective_kw)):
        model.lift(opt.flow.v[i], lp[i], lq[i], dp[i], limit[i], opt.q_mvar[i])
        assert max(float(np.max(c.violation())) for c in model.problem.constraints) < 1e-5
        lifted = model.problem.objective.value
        assert opt.losses_kw[i] * (1 - 2e-5) <= lifted <= opt.losses_kw[i] * (1 + 1e-9)
        assert model.rank_ratios().max() < 1e-9
        if both[i]:
            assert relaxed.bound_kw[i] <= lifted * (1 + CERTIFY_RTOL)


@pytest.mark.parametrize(
    ("change", "message"),
    [("k", "reserve coefficient"), ("nan", "load P contains NaN"), ("shape", "DER P must have shape")],
)
def test_bad_input_is_one_message_before_any_work(ieee13, change, message):
    net, lp, lq, dp = ieee13
    lp, lq, dp = lp[:1].copy(), lq[:1], dp[:1]
    k = 1.5 if change == "k" else 0.0
    if change == "nan":
        lp[0, 3] = np.nan
    if change == "shape":
        dp = dp[:, :-1]
    with pytest.raises(InputError, match=message):
        bound(net, lp, lq, dp, k)


@pytest.fixture(scope="module")
def eulv(tmp_path_factory):
    """eulv with 4 kW PV on every second house, loads and PV as the paper day's 00:00 (night)
    and 12:37 (PV export: the band's top near) — two of `docs/unbalanced_opf_table.py`'s
    steps."""
    tmp = tmp_path_factory.mktemp("eulv_pv")
    with opendss_copy("eulv") as master:
        case = case_with_pv(tmp, master, "eulv", kw=4.0)
    shutil.rmtree(tmp, ignore_errors=True)
    lp, lq, dp, _ = case.stored
    day = paper_day().iloc[[0, 12 * 60 + 37]]
    load, sun = day["load"].to_numpy()[:, None], day["pv"].to_numpy()[:, None]
    return case.network, lp * load, lq * load, dp * sun


@pytest.mark.slow
def test_eulv_chains_are_reduced_exactly_and_the_bound_is_exact_at_night_only(eulv):
    """eulv's buses are mostly chain buses (a shunt-free line in, one line out, nothing
    attached): the relaxation eliminates them (`_reduced`), keeping every load and DER node
    and the band on every node it keeps. The AC optimum lifted into the reduced relaxation
    meets every constraint with the power flow's losses as objective (the merged lines carry
    one current: exact) at rank one, so the relaxation's optimum is below it — up to
    Clarabel's accuracy, `SOLVER_RTOL` here (its answers at this step differ by 3e-6 between
    regularisations; `CLARABEL_ATTEMPTS`). At night it is rank one and meets the AC optimum to that accuracy; at
    noon the solver ends AlmostSolved (no bound), and its point has the constant-PQ loads,
    all above their vmaxpu (OpenDSS's constant-Z there), drawing more than their law — the
    hull s ≥ max(1, w/vmaxpu²), s ≤ chord lets them absorb the PV export locally, and the
    relaxation lies 7 % below (`docs/unbalanced_opf_table.md`)."""
    net, lp, lq, dp = eulv
    model = ThreePhaseSdp(net)
    kept = np.setdiff1d(np.arange(net.n_node), list(model._eliminated))
    assert len(model._eliminated) > 0.7 * net.n_node and len(model._blocks) < 0.3 * len(net.bus_names)
    attached = np.concatenate([net.load_branches.a, net.der_branches.a])
    assert np.isin(attached, kept).all()
    mon_a, _, _ = model._monitored()
    assert set(mon_a.tolist()) == set(kept.tolist())  # the band stays on every node kept
    opt = optimum(net, lp, lq, dp, 0.0)
    assert np.isfinite(opt.losses_kw).all(), opt.status
    limit = q_limits(net, dp, 0.0)
    lb = net.load_branches
    for i in range(len(lp)):
        model.lift(opt.flow.v[i], lp[i], lq[i], dp[i], limit[i], opt.q_mvar[i])
        # to 1e-6 p.u.: the source's Thevenin impedance is near-floating in zero sequence
        # (its delta transformer draws none), so its current solved from the power flow's
        # voltages carries their round-off into the source bus's balance (6e-7 p.u.)
        assert max(float(np.max(c.violation())) for c in model.problem.constraints) < 1e-6
        assert model.problem.objective.value == pytest.approx(opt.losses_kw[i], rel=1e-7)
        assert model.rank_ratios().max() < 1e-9
        solved = model.solve(lp[i], lq[i], dp[i], limit[i])
        if i == 0:  # night: exact up to the solver's accuracy
            assert solved.status == "optimal" and solved.rank_one
            assert solved.bound_kw == pytest.approx(opt.losses_kw[i], rel=SOLVER_RTOL)
        else:  # noon: no bound; the almost-solved point's loads above their law
            assert solved.status == "optimal_inaccurate" and np.isnan(solved.bound_kw)
            s_p = next(v for v in model.problem.variables() if v.name() == "s_p").value
            above = lb.share * lp[i][lb.owner] * (s_p - model._law(model._pair_w(lb.a, lb.b, lb.vbase_v).value)[0])
            assert above.min() > -1e-6 and 1e3 * above.sum() > 1.0  # kW
            assert model.problem.value < 0.95 * opt.losses_kw[i]
