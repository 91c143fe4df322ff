"""The interval bounds' proofs of infeasibility (`formulations.infeasibility`): sound against
AC power flows on SimBench grids (transformer iron losses, taps), never contradicting
IPOPT, and changing nothing in the AC OPF's results but which solver showed the
infeasibility."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.formulations import runner as acopf_module
from opfbench.formulations.infeasibility import SLACK_MUST_EXPORT, VOLTAGES_OUT_OF_REACH, flow_bounds, proven_infeasible
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.problem import VOLTAGE_TOLERANCE, OpfProblem, slack_p_mw, snapshot_data
from opfbench.io import load_case, load_network
from opfbench.powerflow import solve_pf_batch
from opfbench.scenario import Scenario


def june_scenario(code: str, start: str, end: str) -> Scenario:
    """The grid's own profiles from `start` to `end` (local time, 15 min)."""
    case = load_case(f"simbench:{code}")
    times = pd.date_range(start, end, freq="15min", tz="Europe/Berlin")
    return Scenario.of_case(case, times)


def within_limits(net, pf) -> np.ndarray:
    vm = pf.vm
    return pf.converged & np.all(vm >= net.vmin - VOLTAGE_TOLERANCE, axis=1) & np.all(vm <= net.vmax + VOLTAGE_TOLERANCE, axis=1)


@pytest.mark.parametrize(
    "code, surplus",  # MV-urban: two tapped transformers, and no surplus on that day
    [("1-LV-rural1--0-sw", True), ("1-MV-urban--0-sw", False)],
)
def test_the_bounds_hold_at_random_ac_points_within_the_limits(code, surplus):
    """Every AC point within the limits (DER Q uniform in its usable range, and at its
    corners) has its slack P below the bound and every |V|² within the bounds' intervals."""
    scenario = june_scenario(code, "2016-06-21T04:00", "2016-06-21T20:00")
    net = scenario.net
    rng = np.random.default_rng(5)
    for k in (0.0, 0.4):
        data = snapshot_data(scenario, k)
        problem = OpfProblem.of(net, slack_export=False)
        bounds = flow_bounds(problem, data)
        assert not bounds.out_of_reach.any()
        for draw in range(4):
            unit = rng.uniform(-1, 1, data.q_limit.shape) if draw < 2 else rng.choice([-1.0, 1.0], data.q_limit.shape)
            pf = solve_pf_batch(net, scenario.injections(unit * data.q_limit * net.base_mva))
            within = within_limits(net, pf)
            slack_p = (slack_p_mw(net, pf) / net.base_mva) - data.s_fixed[:, net.slack].real  # the slack rule's P, p.u.
            assert within.mean() > 0.5
            assert np.all(slack_p[within] <= bounds.slack_p_hi[within] + 1e-12), (slack_p - bounds.slack_p_hi)[within].max()
            v = pf.vm[within] ** 2
            assert np.all(v >= bounds.v_lo[within] - 1e-12) and np.all(v <= bounds.v_hi[within] + 1e-12)
    assert (proven_infeasible(problem, data) == SLACK_MUST_EXPORT).any() == surplus  # not vacuous: the June noon surplus


def test_the_bounds_hold_with_taps_at_either_end_charging_and_shunts():
    """paper33 with a tap on a branch written parent → child, another on one written child →
    parent (so the child is the tap's side), line charging, bus shunts and a conductance:
    random loads, DER output and Q; every AC point within the limits lies within the bounds."""
    base = load_network("paper33")
    f, t, tap = base.f.copy(), base.t.copy(), base.tap.copy()
    f[7], t[7] = base.t[7], base.f[7]  # branch 7 written child → parent
    tap[[2, 7]] = [0.97, 1.03]
    gs, bs = base.gs_mw.copy(), base.bs_mvar.copy()
    gs[12], bs[20] = 0.01, 0.2
    g = np.zeros(base.n_branch)
    g[2] = 1e-3
    net = base.with_changes(f=f, t=t, tap=tap, b=np.full(base.n_branch, 1e-4), gs_mw=gs, bs_mvar=bs, g=g)
    rng = np.random.default_rng(9)
    n = 60
    scenario = Scenario(net, rng.uniform(0.1, 1.3, n), rng.uniform(0, 1, (n, len(net.ders))) * net.der_rating_mw)
    data = snapshot_data(scenario, 0.0)
    bounds = flow_bounds(OpfProblem.of(net, slack_export=False), data)
    unit = rng.choice([-1.0, 1.0], data.q_limit.shape) * rng.uniform(0.5, 1, data.q_limit.shape)
    pf = solve_pf_batch(net, scenario.injections(unit * data.q_limit * net.base_mva))
    within = within_limits(net, pf)
    assert within.mean() > 0.5
    slack_p = (slack_p_mw(net, pf) / net.base_mva) - data.s_fixed[:, net.slack].real
    assert np.all(slack_p[within] <= bounds.slack_p_hi[within] + 1e-12)
    v = pf.vm[within] ** 2
    assert np.all(v >= bounds.v_lo[within] - 1e-12) and np.all(v <= bounds.v_hi[within] + 1e-12)
    assert not bounds.out_of_reach[within].any()


def test_no_proof_on_a_meshed_feeder_and_no_slack_rule_where_the_slack_may_export():
    net = load_network("paper33-meshed")
    data = snapshot_data(Scenario(net, np.array([0.2]), net.der_rating_mw[None]), 0.0)
    assert list(proven_infeasible(OpfProblem.of(net, False), data)) == [""]
    paper = load_network("paper33")
    data = snapshot_data(Scenario(paper, np.array([0.01]), paper.der_rating_mw[None]), 0.0)
    assert list(proven_infeasible(OpfProblem.of(paper, False), data)) == [SLACK_MUST_EXPORT]
    assert list(proven_infeasible(OpfProblem.of(paper, True), data)) == [""]


def _without_proofs(monkeypatch) -> None:
    monkeypatch.setattr(acopf_module, "proven_infeasible", lambda problem, data: np.full(data.n_snapshots, "", dtype=object))


def _same_results(fast, plain, proven) -> None:
    """`fast` (with the proofs) and `plain` (without) agree on everything but the solver
    status and iteration count of the proven steps."""
    assert list(plain.status) == list(fast.status)
    np.testing.assert_array_equal(plain.q_mvar, fast.q_mvar)
    np.testing.assert_array_equal(plain.losses_kw, fast.losses_kw)
    np.testing.assert_array_equal(plain.solver.iterations[~proven], fast.solver.iterations[~proven])
    assert list(plain.solver.solver_status[~proven]) == list(fast.solver.solver_status[~proven])


def test_acopf_paper_with_the_proofs_equals_it_without(monkeypatch):
    """Over a June day on 1-LV-rural1 the slack bound settles the infeasible daytime steps
    without IPOPT; IPOPT alone (solver "ipopt") reports them infeasible too; every result
    — Q, losses, statuses, the IPOPT steps after them (same warm starts) — is the same as
    without the proofs, only the solver status says what showed the infeasibility."""
    scenario = june_scenario("1-LV-rural1--0-sw", "2016-06-21T06:00", "2016-06-21T18:00")
    options = {"slack_export": False, "fallback": "paper"}
    fast = run_acopf(scenario, 0.0, **options)
    proven = fast.solver.solver_status == SLACK_MUST_EXPORT
    assert 0 < proven.sum() < proven.size and np.all(fast.status[proven] == "infeasible")
    assert np.all(fast.q_mvar[proven] == 0) and np.all(fast.solver.iterations[proven] == 0)
    ipopt = run_acopf(scenario, 0.0, solver="ipopt", **options)
    assert np.all(ipopt.status[proven] == "infeasible")
    assert list(ipopt.status) == list(fast.status)
    _without_proofs(monkeypatch)
    _same_results(fast, run_acopf(scenario, 0.0, **options), proven)


def test_a_voltage_limit_out_of_reach(monkeypatch):
    """1-LV-semiurb5: SimBench gives two LV buses |V| ≤ 1.01 p.u. behind a 1.025 p.u.
    slack; on a June day and night no AC point reaches that. The bounds prove it at every
    step (for the AC OPF with or without the slack rule); IPOPT reports infeasibility
    there too, with the same results otherwise; no random point is within the limits."""
    night = june_scenario("1-LV-semiurb5--0-sw", "2016-06-21T02:00", "2016-06-21T02:15")
    day = june_scenario("1-LV-semiurb5--0-sw", "2016-06-21T13:00", "2016-06-21T13:15")
    net = day.net
    for s in (night, day):
        data = snapshot_data(s, 0.0)
        for export in (True, False):
            assert set(proven_infeasible(OpfProblem.of(net, export), data)) == {VOLTAGES_OUT_OF_REACH}
        unit = np.random.default_rng(2).uniform(-1, 1, data.q_limit.shape)
        assert not within_limits(net, solve_pf_batch(net, s.injections(unit * data.q_limit * net.base_mva))).any()
    fast = run_acopf(day, 0.0)
    assert set(fast.solver.solver_status) == {VOLTAGES_OUT_OF_REACH} and set(fast.status) == {"infeasible"}
    ipopt = run_acopf(day, 0.0, solver="ipopt")
    assert set(ipopt.status) == {"infeasible"} and set(ipopt.solver.solver_status) <= {
        "Infeasible_Problem_Detected → Infeasible_Problem_Detected",
        "Infeasible_Problem_Detected",
    }
    _without_proofs(monkeypatch)
    _same_results(fast, run_acopf(day, 0.0), np.ones(day.n_snapshots, dtype=bool))


@pytest.mark.slow
@pytest.mark.parametrize("code", ["1-MV-rural--0-sw", "1-LV-rural3--0-sw"])
def test_the_bound_never_contradicts_ipopt_over_a_june_day(code):
    """IPOPT on every step (solver "ipopt"), k 0 and 0.4: where the bound proves the
    paper's problem infeasible IPOPT never finds a point (it reports infeasibility, or
    fails otherwise: 1-LV-rural3, k 0.4, 13:00 runs out of iterations — "solver-failed",
    which the bound makes "infeasible" under solver "auto"), and the bound covers nearly
    every step IPOPT reports infeasible."""
    scenario = june_scenario(code, "2016-06-22T00:00", "2016-06-22T23:45")
    for k in (0.0, 0.4):
        proven = proven_infeasible(OpfProblem.of(scenario.net, False), snapshot_data(scenario, k)) != ""
        ipopt = run_acopf(scenario, k, solver="ipopt", slack_export=False, fallback="paper")
        assert proven.any() and set(ipopt.status[proven]) <= {"infeasible", "solver-failed"}
        auto = run_acopf(scenario, k, slack_export=False, fallback="paper")
        assert np.all(auto.status[proven] == "infeasible") and np.all(auto.solver.solver_status[proven] == SLACK_MUST_EXPORT)
        infeasible = ipopt.status == "infeasible"
        print(code, k, f"IPOPT infeasible {infeasible.sum()}, proven by the bound {proven.sum()}")
        assert proven.sum() >= 0.9 * infeasible.sum()


def _numpy_bounds(problem, data):
    """The bounds' passes in plain numpy, branch by branch over all snapshots at once: the
    reference the compiled passes must equal bit for bit."""
    from opfbench.formulations.infeasibility import MARGIN, ROUNDS
    from opfbench.formulations.models.distflow import RadialBranches

    def scaled(c, lo, hi):
        return np.minimum(c * lo, c * hi), np.maximum(c * lo, c * hi)

    def square(lo, hi):
        return np.maximum(np.maximum(lo, -hi), 0.0) ** 2, np.maximum(lo**2, hi**2)

    net, br = problem.net, RadialBranches.of(problem.net)
    p_fixed, q_fixed = data.s_fixed.real.T, data.s_fixed.imag.T
    q_der = problem.der_at_bus @ data.q_limit.T
    g, b = problem.gsh + br.conductance, problem.bsh + br.charging
    lim_lo = np.maximum(net.vmin - VOLTAGE_TOLERANCE, 0.0) ** 2
    lim_hi = (net.vmax + VOLTAGE_TOLERANCE) ** 2
    lim_lo[problem.slack] = lim_hi[problem.slack] = problem.v_slack**2
    v_lo, v_hi = (np.repeat(lim[:, None], data.n_snapshots, axis=1) for lim in (lim_lo, lim_hi))
    drop, ell = {}, {}
    empty = np.zeros(data.n_snapshots, dtype=bool)
    with np.errstate(all="ignore"):
        for _ in range(ROUNDS):
            p_lo, p_hi, q_lo, q_hi = (np.zeros_like(v_lo) for _ in range(4))
            for k in range(br.child.size - 1, -1, -1):
                j, parent = br.child[k], br.parent[k]
                (gv_lo, gv_hi), (bv_lo, bv_hi) = scaled(g[j], v_lo[j], v_hi[j]), scaled(b[j], v_lo[j], v_hi[j])
                pj = (p_lo[j] + gv_lo - p_fixed[j], p_hi[j] + gv_hi - p_fixed[j])
                qj = (q_lo[j] - bv_hi - q_fixed[j] - q_der[j], q_hi[j] - bv_lo - q_fixed[j] + q_der[j])
                (pp_lo, pp_hi), (qq_lo, qq_hi) = square(*pj), square(*qj)
                l_lo = (pp_lo + qq_lo) / (v_hi[j] * br.child_scale[k])
                l_hi = np.where(pp_hi + qq_hi > 0, (pp_hi + qq_hi) / (v_lo[j] * br.child_scale[k]), 0.0)
                xl = scaled(br.x[k], l_lo, l_hi)
                ps, qs = (pj[0] + br.r[k] * l_lo, pj[1] + br.r[k] * l_hi), (qj[0] + xl[0], qj[1] + xl[1])
                xq = scaled(br.x[k], *qs)
                drop[k], ell[k] = (br.r[k] * ps[0] + xq[0], br.r[k] * ps[1] + xq[1]), (l_lo, l_hi)
                p_lo[parent] += ps[0]
                p_hi[parent] += ps[1]
                q_lo[parent] += qs[0]
                q_hi[parent] += qs[1]
            s = problem.slack
            slack_p_hi = p_hi[s] + scaled(g[s], v_lo[s], v_hi[s])[1] - p_fixed[s]
            for k in range(br.child.size):
                j, parent, z2 = br.child[k], br.parent[k], br.r[k] ** 2 + br.x[k] ** 2
                lo = (v_lo[parent] * br.parent_scale[k] - 2 * drop[k][1] + z2 * ell[k][0]) / br.child_scale[k]
                hi = (v_hi[parent] * br.parent_scale[k] - 2 * drop[k][0] + z2 * ell[k][1]) / br.child_scale[k]
                empty |= (lo > lim_hi[j] + MARGIN) | (hi < lim_lo[j] - MARGIN)
                v_lo[j] = np.maximum(np.minimum(lo, lim_hi[j]), lim_lo[j])
                v_hi[j] = np.minimum(np.maximum(hi, lim_lo[j]), lim_hi[j])
    return np.where(np.isnan(slack_p_hi), np.inf, slack_p_hi), v_lo.T, v_hi.T, empty


@pytest.mark.parametrize("code, vmin", [("1-MV-urban--0-sw", None), ("1-LV-rural1--0-sw", 0.0)])
def test_the_compiled_passes_are_numpys_bit_for_bit(code, vmin):
    """`flow_bounds`'s compiled passes compute what the plain numpy passes compute, every
    value to the bit (a tapped MV grid; an LV grid with vmin 0, where ℓ is unbounded)."""
    from dataclasses import replace

    scenario = june_scenario(code, "2016-06-21T00:00", "2016-06-21T23:45")
    net = scenario.net if vmin is None else replace(scenario.net, vmin=np.full(scenario.net.n_bus, vmin))
    data = snapshot_data(scenario, 0.4)
    for export in (False, True):
        problem = OpfProblem.of(net, slack_export=export)
        got = flow_bounds(problem, data)
        for ours, theirs in zip(
            (got.slack_p_hi, got.v_lo, got.v_hi, got.out_of_reach), _numpy_bounds(problem, data), strict=True
        ):
            assert ours.shape == theirs.shape
            assert np.array_equal(np.ascontiguousarray(ours).view(np.uint8), np.ascontiguousarray(theirs).view(np.uint8))
