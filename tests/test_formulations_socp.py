"""SOCP relaxation (cvxpy + Clarabel): a valid lower bound, exact on radial feeders."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest

from opfbench.errors import NetworkError
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.models.conic import data_vector
from opfbench.formulations.models.distflow import DistFlowSocp
from opfbench.formulations.models.jabr import JabrSocp
from opfbench.formulations.opf_strategies import run_acopf, run_socp
from opfbench.formulations.problem import snapshot_data
from opfbench.io import load_network
from opfbench.scenario import Scenario

BOUND_SLACK = 1e-6  # relative: solver tolerances of both sides


def random_scenario(net, n: int, seed: int) -> Scenario:
    rng = np.random.default_rng(seed)
    return Scenario(net, rng.uniform(0.3, 1.3, n), rng.uniform(0.0, 1.0, (n, len(net.ders))) * net.der_rating_mw)


@pytest.mark.parametrize("case, n, exact", [("paper33", 20, True), ("case69-der", 8, True), ("paper33-meshed", 20, False)])
def test_lower_bound_below_ac_opf(case, n, exact):
    net = load_network(case)
    scenario = random_scenario(net, n, seed=7)
    for k in (0.0, 0.5):
        opf = run_acopf(scenario, k)
        ok = opf.status == "ok"
        assert ok.sum() >= n - 2, opf.status
        # Anything else must be a heavy-load snapshot the relaxation proves infeasible.
        assert np.all(opf.status[~ok] == "infeasible")
        assert np.all(opf.extra["socp_status"][~ok] == "PrimalInfeasible")
        lower, losses = opf.lower_bound_kw[ok], opf.losses_kw[ok]
        assert np.all(np.isfinite(lower))
        assert np.all(lower <= losses * (1 + BOUND_SLACK)), np.max(lower / losses)
        gap = (losses - lower) / losses
        if exact:
            assert gap.max() <= 1e-5, gap.max()
            assert np.max(opf.extra["relaxation_gap"][ok]) < 1e-6  # solver-tolerance level
        else:
            assert gap.max() > 1e-4  # Jabr drops the mesh's angle conditions: a real gap


def test_relaxation_setpoints_are_optimal_when_exact():
    net = load_network("paper33")
    scenario = random_scenario(net, 10, seed=3)
    socp, opf = run_socp(scenario, 0.0), run_acopf(scenario, 0.0)
    assert np.all(socp.status == "ok") and socp.solver.model == "distflow"
    np.testing.assert_allclose(socp.losses_kw, opf.losses_kw, rtol=1e-5)
    assert np.all(socp.lower_bound_kw <= socp.losses_kw * (1 + BOUND_SLACK))
    assert np.all(socp.extra["ac_feasible"])


def test_meshed_feeder_uses_jabr_and_its_point_is_ac_evaluated():
    net = load_network("paper33-meshed")
    res = run_socp(Scenario.snapshot(net, 1.0, 0.8), 0.0)
    assert res.solver.model == "jabr" and res.status[0] == "ok"
    assert res.lower_bound_kw[0] < res.losses_kw[0]


def test_jabr_and_distflow_agree_on_a_radial_feeder():
    net = load_network("paper33")
    data = snapshot_data(Scenario.snapshot(net, 0.9, 0.6), 0.2)
    args = (data.s_fixed[0], data.q_limit[0])
    dist, jabr = DistFlowSocp(net).solve(*args), JabrSocp(net).solve(*args)
    assert jabr.objective_kw == pytest.approx(dist.objective_kw, rel=1e-6)
    np.testing.assert_allclose(jabr.q_pu, dist.q_pu, atol=1e-6)


@pytest.mark.parametrize("model", [DistFlowSocp, JabrSocp])
def test_direct_clarabel_path_matches_cvxpy_solve(model):
    """The data-as-offset path (the full program) equals cvxpy's own solve with the data
    variables pinned; the screened answer has the same optimum: its bound within 5e-7
    relative (Clarabel's tolerances on two different programs; measured 1.2e-8 for
    DistFlow, 3.1e-7 for Jabr). Q within 1e-5 p.u. for both: the losses are flat in Q near
    the optimum, so 1e-8 in the objective leaves Q loose (measured up to 1.0e-6 for the
    full program, 5.6e-6 for the screened Jabr answer, against cvxpy's defaults)."""
    net = load_network("paper33")
    relax = model(net)
    program = relax.program
    for scale in (0.5, 1.2):
        data = snapshot_data(Scenario.snapshot(net, scale, 0.7), 0.0)
        pins = [relax.p_fixed == data.s_fixed[0].real, relax.q_fixed == data.s_fixed[0].imag, relax.q_limit == data.q_limit[0]]
        pinned = cp.Problem(relax.cvxpy_problem.objective, relax.cvxpy_problem.constraints + pins)
        pinned.solve(solver=cp.CLARABEL)
        assert pinned.status == "optimal"
        b = program.offsets(data_vector(data.s_fixed, data.q_limit))[0]
        full, statuses, _ = program.full.solve(b)
        assert statuses == ["Solved"]
        assert min(full.obj_val, full.obj_val_dual) == pytest.approx(pinned.value, rel=1e-7)
        np.testing.assert_allclose(program.reader(np.array(full.x))(relax.q), relax.q.value, atol=1e-5)
        answer = relax.solve(data.s_fixed[0], data.q_limit[0])
        assert answer.objective_kw == pytest.approx(pinned.value, rel=5e-7)
        np.testing.assert_allclose(answer.q_pu, relax.q.value, atol=1e-5)


def test_infeasible_voltage_band_is_certified():
    net = load_network("paper33")
    tight = net.with_changes(vmin=np.full(net.n_bus, 0.99), vmax=np.full(net.n_bus, 1.0))
    res = run_socp(Scenario.snapshot(tight, 1.2, 0.5), 0.0)
    assert res.status[0] == "infeasible" and res.solver.fallback[0] == "no-action"
    assert np.isnan(res.lower_bound_kw[0]) and np.all(res.q_mvar == 0)


def test_distflow_models_transformers_exactly():
    """Taps at a branch's parent or child end, a phase shift and a shunt conductance (a
    transformer's iron losses) on a radial feeder: DistFlow's bound equals Jabr's, the AC
    losses of its setpoints and the AC OPF's losses."""
    net = load_network("paper33")
    k = np.arange(net.n_branch)
    flip = k == 10  # its tap at the child end
    tapped = net.with_changes(
        f=np.where(flip, net.t, net.f),
        t=np.where(flip, net.f, net.t),
        tap=np.select([k == 3, flip], [1.02, 0.97], 1.0),
        shift=np.where(k == 5, 30.0, 0.0),
        g=np.where(k == 0, 0.002, 0.0),
    )
    scenario = Scenario.snapshot(tapped, 1.0, 0.8)
    data = snapshot_data(scenario, 0.0)
    args = (data.s_fixed[0], data.q_limit[0])
    dist, jabr = DistFlowSocp(tapped).solve(*args), JabrSocp(tapped).solve(*args)
    assert type(build_problem_model("relaxation", tapped)) is DistFlowSocp and dist.optimal and jabr.optimal
    assert dist.objective_kw == pytest.approx(jabr.objective_kw, rel=1e-6)
    socp = run_socp(scenario, 0.0)
    assert socp.losses_kw[0] == pytest.approx(dist.objective_kw, rel=1e-6)
    assert run_acopf(scenario, 0.0).losses_kw[0] == pytest.approx(dist.objective_kw, rel=1e-6)
    plain = snapshot_data(Scenario.snapshot(net, 1.0, 0.8), 0.0)
    assert abs(DistFlowSocp(net).solve(plain.s_fixed[0], plain.q_limit[0]).objective_kw - dist.objective_kw) > 1.0
    with pytest.raises(NetworkError, match="radial"):
        DistFlowSocp(load_network("paper33-meshed"))
    assert (
        type(build_problem_model("relaxation", net)) is DistFlowSocp
        and type(build_problem_model("relaxation", load_network("paper33-meshed"))) is JabrSocp
    )


def test_line_charging_is_modelled_exactly():
    """With π-model charging, DistFlow (charging as bus shunts) and the exact AC OPF agree."""
    base = load_network("paper33")
    net = base.with_changes(b=np.full(base.n_branch, 0.002))
    scenario = Scenario.snapshot(net, 1.0, 0.8)
    opf = run_acopf(scenario, 0.0)
    assert opf.status[0] == "ok"
    assert opf.lower_bound_kw[0] == pytest.approx(opf.losses_kw[0], rel=1e-5)
    assert opf.losses_kw[0] != pytest.approx(run_acopf(Scenario.snapshot(base, 1.0, 0.8), 0.0).losses_kw[0], abs=1e-2)
