"""The certified fast path of the AC OPF, the shared SOCP solves, and the problem's checks."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from opfbench.errors import InputError, NetworkError
from opfbench.formulations import runner as acopf_module
from opfbench.formulations import solves as relaxation_module
from opfbench.formulations.infeasibility import VOLTAGES_OUT_OF_REACH
from opfbench.formulations.model import build_problem_model, built, model_for
from opfbench.formulations.models.conic import ConicModel, data_vector
from opfbench.formulations.opf_strategies import run_acopf, run_socp
from opfbench.formulations.policy import CERTIFY_RTOL
from opfbench.formulations.problem import snapshot_data
from opfbench.formulations.solver_cache import EXACT_KEY_BYTES, PER_THREAD, SolveCache, per_thread
from opfbench.formulations.solves import relaxation_solves
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario


def random_snapshots(case: str, n: int, seed: int = 7) -> Scenario:
    """n independent snapshots: load scale U[0.2, 1.2], each DER's P U[0, rating]."""
    net = load_network(case)
    rng = np.random.default_rng(seed)
    return Scenario(net, rng.uniform(0.2, 1.2, n), rng.uniform(0.0, 1.0, (n, len(net.ders))) * net.der_rating_mw)


def _compare(scenario: Scenario, k: float) -> float:
    """Fast path vs IPOPT on every snapshot: same statuses, losses within 1e-6 relative,
    every fast-path point certified by one of the two solvers. Returns the certified share."""
    fast = run_acopf(scenario, k)
    ipopt = run_acopf(scenario, k, solver="ipopt")
    assert list(fast.status) == list(ipopt.status)
    ok = fast.status == "ok"
    np.testing.assert_allclose(fast.losses_kw[ok], ipopt.losses_kw[ok], rtol=1e-6, atol=0)
    by = fast.solver.certified_by
    assert set(by[ok]) <= {"socp", "ipopt"} and set(ipopt.solver.certified_by[ok]) == {"ipopt"}
    socp = by == "socp"
    assert np.all(fast.solver.iterations[socp] == 0) and np.all(fast.solver.iterations[by == "ipopt"] > 0)
    assert np.all(fast.losses_kw[socp] <= fast.lower_bound_kw[socp] * (1 + CERTIFY_RTOL))
    assert np.all(fast.extra["ac_feasible"][ok])
    return float(socp.mean())


@pytest.mark.parametrize("case, n", [("paper33", 30), ("case69-der", 20), ("case141-der", 8)])
def test_fast_path_equals_ipopt_on_random_snapshots(case, n):
    share = _compare(random_snapshots(case, n), 0.0)
    assert share > 0.5, share  # the relaxation is exact on these radial feeders


@pytest.mark.slow
@pytest.mark.parametrize("case", ["paper33", "case69-der", "case141-der"])
def test_fast_path_equals_ipopt_on_100_random_snapshots_and_the_paper_day(case):
    from opfbench.bench.paper_day import paper_day_scenario

    shares = {"random": _compare(random_snapshots(case, 100, seed=11), 0.0), "paper day": _compare(paper_day_scenario(case), 0.0)}
    print(case, "certified by the SOCP:", shares)
    assert shares["paper day"] >= 0.99, shares


def test_reported_objective_never_below_the_bound():
    """IPOPT with bound_relax_factor 0: its Q stays within the limits, so neither its own
    objective nor the AC-evaluated losses fall below the SOCP's bound by more than the
    bound's own accuracy (Clarabel's tolerances, ~1e-8 relative)."""
    scenario = random_snapshots("case69-der", 15, seed=3)
    res = run_acopf(scenario, 0.3, solver="ipopt")
    tol = 5e-8 * np.abs(res.lower_bound_kw)
    assert np.all(res.solver.objective_kw >= res.lower_bound_kw - tol)
    assert np.all(res.losses_kw >= res.lower_bound_kw - tol)
    usable = (1 - 0.3) * scenario.qmax_mvar()
    assert np.all(np.abs(res.q_mvar) <= usable)


def _count_solves(monkeypatch) -> list:
    """Count Clarabel solves, with an empty solve cache."""
    calls = []
    real = ConicModel.solve_data

    def counting(self, thetas):
        calls.extend([1] * len(np.atleast_2d(thetas)))
        return real(self, thetas)

    monkeypatch.setattr(ConicModel, "solve_data", counting)
    relaxation_module.forget_solves()
    return calls


def test_acopf_and_socp_share_one_clarabel_solve_per_snapshot(monkeypatch):
    calls = _count_solves(monkeypatch)
    scenario = random_snapshots("paper33", 6)
    acopf = run_strategy("acopf", scenario, 0.2)
    socp = run_strategy("socp", scenario, 0.2)
    assert len(calls) == 6
    np.testing.assert_array_equal(acopf.lower_bound_kw, socp.lower_bound_kw)
    run_strategy("socp", scenario, 0.4)  # another k: another problem
    assert len(calls) == 12
    again = run_strategy("socp", Scenario(scenario.net, scenario.load_scale, scenario.der_p_mw), 0.2)
    assert len(calls) == 12  # a new scenario object with the same data: solved by data already
    np.testing.assert_array_equal(again.q_mvar, socp.q_mvar)


def test_a_solve_depends_on_its_data_alone():
    """What makes sharing solves by data exact: the same data solved after different
    histories on different solver objects gives the same digits."""
    scenario = random_snapshots("paper33", 12, seed=3)
    data = snapshot_data(scenario, 0.3)
    thetas = data_vector(data.s_fixed, data.q_limit)
    a, b = build_problem_model("relaxation", scenario.net), build_problem_model("relaxation", scenario.net)
    forward = a.solve_data(thetas)  # in order, in one call
    backward = [b.solve_data(t)[0] for t in thetas[::-1]][::-1]  # one by one, in reverse
    for x, y in zip(forward, backward, strict=True):
        np.testing.assert_array_equal(x.q_pu, y.q_pu)
        assert x.objective_kw == y.objective_kw and x.slack_p_pu == y.slack_p_pu


def test_paper_slack_rule_reuses_the_unrestricted_optimum_only_where_the_slack_imports(monkeypatch):
    """Light load and DER at full output make the slack export on some snapshots: only those
    are solved again under slack P ≥ 0; every snapshot agrees with a relaxation built with
    the rule from the start."""
    net = load_network("paper33")
    rng = np.random.default_rng(5)
    n = 16
    scenario = Scenario(net, rng.uniform(0.1, 1.0, n), rng.uniform(0.5, 1.0, (n, len(net.ders))) * net.der_rating_mw)
    calls = _count_solves(monkeypatch)
    free = relaxation_solves(scenario, 0.0, slack_export=True)
    exporting = np.array([s.optimal and s.slack_p_pu < 0 for s in free])
    assert 0 < exporting.sum() < n
    ruled = relaxation_solves(scenario, 0.0, slack_export=False)
    assert len(calls) == n + exporting.sum()
    assert all((r is f) != e for r, f, e in zip(ruled, free, exporting, strict=True))
    direct = build_problem_model("relaxation", net, slack_export=False)
    data = snapshot_data(scenario, 0.0)
    for i, r in enumerate(ruled):
        ref = direct.solve(data.s_fixed[i], data.q_limit[i])
        assert r.outcome == ref.outcome
        if ref.optimal:
            assert r.objective_kw == pytest.approx(ref.objective_kw, rel=1e-6)
            assert r.slack_p_pu >= -1e-7


def test_paper_setup_takes_the_fast_path_unless_ipopt_is_asked_for():
    scenario = random_snapshots("paper33", 4)
    fast = run_strategy("acopf-paper", scenario, 0.0)
    assert "socp" in set(fast.solver.certified_by)
    res = run_strategy("acopf-paper", scenario, 0.0, solver="ipopt")
    assert np.all(res.solver.iterations > 0)
    assert set(res.solver.certified_by) <= {"ipopt", ""}


def test_solver_objects_are_not_shared_between_threads_or_callers():
    net = load_network("paper33")
    assert build_problem_model("relaxation", net) is not build_problem_model("relaxation", net)
    relaxation, exact = model_for("relaxation", net), model_for("exact", net)
    assert built(relaxation, net) is built(relaxation, net) and built(exact, net) is built(exact, net)
    other = {}
    thread = threading.Thread(target=lambda: other.update(socp=built(relaxation, net), opf=built(exact, net)))
    thread.start()
    thread.join()
    assert other["socp"] is not built(relaxation, net) and other["opf"] is not built(exact, net)


@pytest.mark.parametrize("run", [run_acopf, run_socp])
def test_k_as_an_array_is_refused(run):
    with pytest.raises(InputError, match="one number"):
        run(random_snapshots("paper33", 2), np.array([0.1, 0.2]))


@pytest.mark.parametrize("run", [run_acopf, run_socp])
def test_vmin_above_vmax_is_a_network_error_before_any_solve(run):
    """Refused with the bus and both limits named — by the network itself where it checks
    its limits, else by the OPF problem before any model is built."""
    net = load_network("paper33")
    vmin = net.vmin.copy()
    vmin[7] = net.vmax[7] + 0.05
    with pytest.raises(NetworkError, match=rf"bus {net.bus_ids[7]} has .*1\.15.*1\.1"):
        run(Scenario.snapshot(net.with_changes(vmin=vmin)), 0.0)


def test_unknown_solver_option_is_refused():
    with pytest.raises(InputError, match="unknown AC OPF solver 'knitro'"):
        run_acopf(random_snapshots("paper33", 1), 0.0, solver="knitro")


def test_per_thread_cache_keeps_the_most_recent_objects():
    net = load_network("paper33")
    first = per_thread(net, "probe-0", object)
    assert per_thread(net, "probe-0", object) is first
    for i in range(1, PER_THREAD + 1):
        per_thread(net, f"probe-{i}", object)
    assert per_thread(net, "probe-0", object) is not first  # dropped, built afresh


def test_an_infeasible_relaxation_settles_the_step_without_ipopt(monkeypatch):
    """Twice the nominal load and no Q (k = 1) pull paper33 below 0.9 p.u.: the interval
    bounds prove the AC OPF infeasible before the relaxation is solved, and without them
    the SOCP does; either way the fast path records it without IPOPT; IPOPT agrees."""
    net = load_network("paper33")
    scenario = Scenario(net, np.array([1.0, 2.0, 3.0]), np.zeros((3, len(net.ders))))
    fast = run_acopf(scenario, 1.0)
    assert list(fast.status) == ["ok", "infeasible", "infeasible"]
    assert list(fast.solver.solver_status[1:]) == [VOLTAGES_OUT_OF_REACH] * 2
    monkeypatch.setattr(acopf_module, "proven_infeasible", lambda problem, data: np.full(data.n_snapshots, "", dtype=object))
    by_socp = run_acopf(scenario, 1.0)
    assert list(by_socp.solver.solver_status[1:]) == ["PrimalInfeasible"] * 2
    for res in (fast, by_socp):
        assert list(res.status) == list(fast.status) and np.array_equal(res.losses_kw, fast.losses_kw)
        assert np.all(res.solver.iterations[1:] == 0) and np.all(res.q_mvar[1:] == 0)
    ipopt = run_acopf(Scenario(net, scenario.load_scale, scenario.der_p_mw), 1.0, solver="ipopt")
    assert list(ipopt.status) == list(fast.status) and np.all(ipopt.solver.iterations[1:] > 0)


def test_the_solve_cache_is_keyed_on_the_data_and_bounded(paper33):
    """Short data vectors are their own keys (exact), long ones a 16-byte digest; equal data
    give equal keys whatever array holds them; the least recently used entries go first."""
    short, long = np.arange(6.0).reshape(2, 3), np.ones((1, EXACT_KEY_BYTES // 8 + 1))
    keys = SolveCache.keys(paper33, "o", short)
    assert [k[2] for k in keys] == [row.tobytes() for row in short]
    assert SolveCache.keys(paper33, "o", short.copy()) == keys and SolveCache.keys(paper33, "p", short) != keys
    assert len(SolveCache.keys(paper33, "o", long)[0][2]) == 16
    cache: SolveCache[str] = SolveCache(limit_bytes=2 * (SolveCache.KEY_BYTES + 24 + 1), size=len)
    a, b, c = SolveCache.keys(paper33, "o", np.arange(9.0).reshape(3, 3))
    cache.put_many([(a, "A"), (b, "B")])
    assert cache.get_many([a, c]) == ["A", None]  # a is now the most recent
    cache.put_many([(c, "C")])  # over the limit: b, the least recently used, goes
    assert cache.get_many([a, b, c]) == ["A", None, "C"]
