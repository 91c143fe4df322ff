"""LinDistFlow (`formulations/models/lindistflow.py`) — the formulation seam's proof: one
model file, registered as an approximation by its own decorator, its quadratic objective
solved through the Clarabel adapter, checked against a textbook LinDistFlow written here in
plain cvxpy and against the AC power flow and the SOCP bound."""

from __future__ import annotations

import json

import cvxpy as cp
import numpy as np
import pytest

from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.formulations.model import model_for
from opfbench.formulations.problem import snapshot_data
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy, spec
from opfbench.registry.references import DEFAULT_RUN
from opfbench.scenario import Scenario


def _textbook(net, s_fixed: np.ndarray, q_limit: np.ndarray) -> tuple[np.ndarray, float]:
    """Baran–Wu's LinDistFlow bus by bus (a feeder without taps, charging or shunts): the
    flow into bus j's branch is what j and the buses below it take, v_j = v_i − 2(rP + xQ);
    minimize Σ r·(P² + Q²)/v_slack² (kW). Returns the DER Q (p.u.) and the objective."""
    n, slack = net.n_bus, net.slack
    q = cp.Variable(len(net.ders))
    p_in, q_in, v = cp.Variable(n), cp.Variable(n), cp.Variable(n)  # flow into each bus's parent branch
    der_q = [sum(q[d] for d in range(len(net.ders)) if net.der_bus[d] == j) for j in range(n)]
    rows = [v[slack] == net.v_slack**2, v >= net.vmin**2, v <= net.vmax**2, cp.abs(q) <= q_limit]
    r, x = np.zeros(n), np.zeros(n)
    for j in range(n):
        if j == slack:
            continue
        children = [c for c in range(n) if c != slack and net.parent[c] == j]
        branch = net.parent_branch[j]
        r[j], x[j] = net.r[branch], net.x[branch]
        rows += [
            p_in[j] == sum(p_in[c] for c in children) - s_fixed[j].real,
            q_in[j] == sum(q_in[c] for c in children) - s_fixed[j].imag - der_q[j],
            v[j] == v[net.parent[j]] - 2 * (r[j] * p_in[j] + x[j] * q_in[j]),
        ]
    losses = net.base_mva * 1e3 * cp.sum(cp.multiply(r / net.v_slack**2, cp.square(p_in) + cp.square(q_in)))
    problem = cp.Problem(cp.Minimize(losses), rows)
    problem.solve(solver=cp.CLARABEL)
    assert problem.status == "optimal"
    return q.value, problem.value


@pytest.fixture(scope="module")
def paper33():
    net = load_network("paper33")
    assert np.all(net.tap == 1) and not net.b.any() and not net.gs_mw.any() and not net.bs_mvar.any()  # the textbook's feeder
    return net


@pytest.mark.parametrize("load_scale, der_scale, k", [(1.0, 0.8, 0.0), (0.6, 1.0, 0.4), (1.3, 0.2, 0.0)])
def test_lindistflow_is_the_textbook_model(paper33, load_scale, der_scale, k):
    """The model's setpoints and objective are plain cvxpy's on the same equations — with
    its quadratic objective ignored the adapter would answer something else entirely."""
    scenario = Scenario.snapshot(paper33, load_scale, der_scale)
    data = snapshot_data(scenario, k)
    q_ref, objective_ref = _textbook(paper33, data.s_fixed[0], data.q_limit[0])
    res = run_strategy("lindistflow", scenario, k)
    assert res.status[0] == "ok" and res.solver.model == "lindistflow" and res.solver.meaning == "estimate"
    np.testing.assert_allclose(res.q_mvar[0], q_ref * paper33.base_mva, atol=1e-5)
    assert res.solver.objective_kw[0] == pytest.approx(objective_ref, rel=1e-6)
    assert np.abs(res.q_mvar[0]).max() > 0.05  # the optimum moves Q, far from Q ≈ 0


def test_lindistflow_estimates_the_losses_and_no_bound_is_claimed(paper33):
    """AC-evaluated like every formulation: its AC losses are at least the SOCP's certified
    bound (and, on paper33, within 1 % of it: near-optimal setpoints), its estimate within
    15 % of them (it drops the losses from the balance: low at heavy load); it gives no
    lower bound and certifies nothing."""
    scenario = Scenario.from_profiles(paper33, np.linspace(0.5, 1.2, 6), np.linspace(1.0, 0.1, 6), np.full(6, 0.6))
    lin, socp = run_strategy("lindistflow", scenario, 0.0), run_strategy("socp", scenario, 0.0)
    assert np.all(lin.status == "ok") and lin.lower_bound_kw is None and set(lin.solver.certified_by) == {""}
    assert np.all(lin.losses_kw >= socp.lower_bound_kw * (1 - 1e-6))
    assert np.all(lin.losses_kw <= socp.lower_bound_kw * 1.01)
    np.testing.assert_allclose(lin.solver.objective_kw, lin.losses_kw, rtol=0.15)


def test_lindistflow_is_an_approximation_of_its_own_not_in_the_default_grid(paper33):
    entry = spec("lindistflow")
    assert entry.kind == "formulation" and entry.role == "approximation" and entry.meaning == "estimate"
    assert entry.bound_rank is None and entry.supports == ("radial",) and "lindistflow" not in DEFAULT_RUN
    assert model_for("relaxation", paper33).name == "distflow" and model_for("exact", paper33).name == "polar-ac"
    with pytest.raises(InputError, match="runs on radial networks; paper33-meshed is meshed"):
        entry.check_network(load_network("paper33-meshed"))


def test_snapshot_json_says_what_the_objective_is(capsys):
    assert main(["snapshot", "paper33", "--strategy", "lindistflow", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "ok" and out["model"] == "lindistflow" and out["objective"] == "estimate"
    assert out["objective_kw"] > 0 and out["certified_by"] == "" and "lower_bound_kw" not in out
