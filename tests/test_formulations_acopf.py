"""AC OPF (CasADi + IPOPT): reference optimum, AC feasibility, failure policy, warm start."""

from __future__ import annotations

import json
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from opfbench.bench.opf import daily_scenario
from opfbench.capability import qmax
from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.formulations import runner
from opfbench.formulations.infeasibility import SLACK_MUST_EXPORT, VOLTAGES_OUT_OF_REACH
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.models import polar_ac
from opfbench.formulations.models.polar_ac import AcOpf
from opfbench.formulations.opf_strategies import run_acopf, run_socp
from opfbench.formulations.problem import VOLTAGE_TOLERANCE, snapshot_data
from opfbench.powerflow import solve_pf
from opfbench.result import STATUSES
from opfbench.scenario import Scenario


@pytest.fixture(scope="module")
def nominal(paper33):
    return run_acopf(Scenario.snapshot(paper33, 1.0, 0.8), 0.0, solver="ipopt")


def test_paper33_reference_optimum(paper33, nominal):
    # Independent reference: MATPOWER with tight tolerances, 33.23 kW at nominal load,
    # DER P = 0.48 MW, k = 0 (PV limits min(0.36, 0.36) MVAr, DFIG 0.4 MVAr).
    limits = qmax(paper33.der_kinds, np.full(5, 0.48), paper33.der_rating_mw)
    np.testing.assert_allclose(limits, [0.36, 0.36, 0.36, 0.36, 0.4])
    assert nominal.status[0] == "ok"
    assert nominal.losses_kw[0] == pytest.approx(33.23, abs=0.02)
    assert np.all(np.abs(nominal.q_mvar[0]) <= limits + 1e-12)
    assert nominal.solver.iterations[0] > 0 and nominal.solver.solve_ms[0] > 0


def test_opf_point_is_reproduced_by_ac_power_flow(paper33, nominal):
    scenario = Scenario.snapshot(paper33, 1.0, 0.8)
    pf = solve_pf(paper33, scenario.injections(nominal.q_mvar)[0])
    assert pf.converged
    assert float(pf.losses_kw) == pytest.approx(nominal.solver.objective_kw[0], abs=1e-3)
    assert np.all(pf.vm >= paper33.vmin - VOLTAGE_TOLERANCE)
    assert np.all(pf.vm <= paper33.vmax + VOLTAGE_TOLERANCE)
    assert nominal.extra["ac_feasible"][0]


def test_reserve_shrinks_the_feasible_set(paper33):
    scenario = Scenario.snapshot(paper33, 1.0, 0.8)
    losses = [float(run_acopf(scenario, k).losses_kw[0]) for k in (0.0, 0.4, 0.8)]
    assert losses[0] < losses[1] < losses[2]
    res = run_acopf(scenario, 0.8)
    limit = 0.2 * qmax(paper33.der_kinds, scenario.der_p_mw[0], paper33.der_rating_mw)
    assert np.all(np.abs(res.q_mvar[0]) <= limit + 1e-12)


@pytest.mark.parametrize("k", [-0.1, 1.5, np.nan])
def test_reserve_outside_unit_interval_is_refused(paper33, k):
    with pytest.raises(InputError, match="reserve coefficient"):
        run_acopf(Scenario.snapshot(paper33, 1.0, 0.8), k)


def test_unknown_fallback_policy_is_refused(paper33):
    with pytest.raises(InputError, match="failure policy"):
        run_acopf(Scenario.snapshot(paper33, 1.0, 0.8), 0.0, fallback="retry")


@pytest.mark.parametrize("policy", ["chain", "paper"])
def test_voltage_band_too_tight_is_infeasible(paper33, policy):
    tight = paper33.with_changes(vmin=np.full(paper33.n_bus, 0.99), vmax=np.full(paper33.n_bus, 1.0))
    scenario = Scenario.snapshot(tight, 1.2, 0.5)
    res = run_acopf(scenario, 0.0, fallback=policy)
    assert res.status[0] == "infeasible"
    assert res.solver.fallback[0] == "no-action"
    # the interval bounds prove it before the relaxation is solved (`infeasibility`)
    assert res.solver.solver_status[0] == VOLTAGES_OUT_OF_REACH and res.extra["socp_status"][0] == ""
    assert np.all(res.q_mvar == 0) and np.isfinite(res.losses_kw[0])  # no action's losses, labelled
    assert not res.extra["ac_feasible"][0]
    ipopt = run_acopf(scenario, 0.0, fallback=policy, solver="ipopt")  # every step solved: the relaxation proves it too
    assert ipopt.status[0] == "infeasible" and ipopt.extra["socp_status"][0] == "PrimalInfeasible"
    assert "Infeasible" in ipopt.solver.solver_status[0]
    np.testing.assert_array_equal(ipopt.losses_kw, res.losses_kw)


def test_reverse_flow_without_slack_export_is_infeasible(paper33):
    scenario = Scenario.snapshot(paper33, 0.2, 1.0)
    proven = run_acopf(scenario, 0.0, slack_export=False)  # the interval bounds prove it (`infeasibility`)
    assert proven.status[0] == "infeasible" and proven.solver.solver_status[0] == SLACK_MUST_EXPORT
    res = run_acopf(scenario, 0.0, slack_export=False, solver="ipopt")
    assert res.status[0] == "infeasible"
    assert res.solver.fallback[0] == "no-action"
    assert not res.extra["ac_feasible"][0]
    np.testing.assert_array_equal(proven.losses_kw, res.losses_kw)
    # The relaxation is feasible but only by inventing losses (not exact): its bound
    # says the surplus must be burnt, its setpoints still export. The bound holds for
    # points meeting the limits, and no action (the point applied) does not: the result
    # gives no bound on its losses, the relaxation's value is kept beside.
    assert np.isnan(res.lower_bound_kw[0]) and res.losses_kw[0] < 200
    assert res.extra["relaxation_bound_kw"][0] > 1000
    assert res.extra["relaxation_gap"][0] > 1e-3
    exporting = run_acopf(scenario, 0.0, slack_export=True)
    assert exporting.status[0] == "ok" and exporting.extra["ac_feasible"][0]


def test_slack_export_off_is_harmless_under_normal_load(paper33, nominal):
    res = run_acopf(Scenario.snapshot(paper33, 1.0, 0.8), 0.0, slack_export=False)
    assert res.status[0] == "ok"
    assert res.losses_kw[0] == pytest.approx(nominal.losses_kw[0], abs=1e-4)


class _Failing:
    """An AcOpf stand-in whose warm (or all) solves fail — exercises the policy logic."""

    def __init__(self, real: AcOpf, fail_cold: bool):
        self.real, self.fail_cold = real, fail_cold

    def solve(self, s_fixed, q_limit, start=None):
        sol = self.real.solve(s_fixed, q_limit, start)
        if start is not None or self.fail_cold:
            return replace(sol, success=False, status="Maximum_Iterations_Exceeded")
        return sol


def _with_failing(monkeypatch, net, fail_cold):
    real = build_problem_model("exact", net, True)
    monkeypatch.setattr(runner, "built", lambda *_: _Failing(real, fail_cold))


def test_chain_recovers_from_warm_failure_with_cold_start(paper33, monkeypatch):
    _with_failing(monkeypatch, paper33, fail_cold=False)
    res = run_acopf(daily_scenario(paper33, 4), 0.0, solver="ipopt")
    assert list(res.status) == ["ok", "fallback-cold", "fallback-cold", "fallback-cold"]
    assert list(res.solver.fallback) == ["none", "cold", "cold", "cold"]
    assert list(res.extra["warm_start"]) == [False, True, True, True]
    assert res.solver.solver_status[1] == "Maximum_Iterations_Exceeded → Solve_Succeeded"


def test_chain_falls_back_to_socp_then_paper_to_no_action(paper33, monkeypatch, nominal):
    _with_failing(monkeypatch, paper33, fail_cold=True)
    scenario = Scenario.snapshot(paper33, 1.0, 0.8)
    chain = run_acopf(scenario, 0.0, solver="ipopt")
    assert chain.status[0] == "fallback-socp" and chain.solver.fallback[0] == "socp"
    socp = run_socp(scenario, 0.0)
    np.testing.assert_allclose(chain.q_mvar, socp.q_mvar)
    assert chain.losses_kw[0] == pytest.approx(nominal.losses_kw[0], rel=1e-5)  # exact relaxation
    paper = run_acopf(scenario, 0.0, fallback="paper", solver="ipopt")
    assert paper.status[0] == "fallback-no-action" and paper.solver.fallback[0] == "no-action"
    assert np.all(paper.q_mvar == 0) and paper.losses_kw[0] > nominal.losses_kw[0] + 1


def test_mx_and_sx_models_agree(paper33, monkeypatch):
    """The NLP in CasADi MX (large feeders) is the SX one's: same optimum and setpoints."""
    scenario = daily_scenario(paper33, 4)
    data = snapshot_data(scenario, 0.3)
    sx = build_problem_model("exact", paper33)
    monkeypatch.setattr(polar_ac, "MX_MIN_BUSES", 0)
    mx = build_problem_model("exact", paper33)
    assert isinstance(mx.ipopt.nlp["x"], ca.MX) and isinstance(sx.ipopt.nlp["x"], ca.SX)
    for i in range(4):
        a, b = (o.solve(data.s_fixed[i], data.q_limit[i]) for o in (sx, mx))
        assert a.success and b.success
        assert b.objective_kw == pytest.approx(a.objective_kw, rel=1e-8)
        np.testing.assert_allclose(b.q_pu, a.q_pu, atol=1e-7)


def test_warm_start_saves_iterations(paper33):
    """Warm vs cold IPOPT over a smooth day (figures in the report; bench for 200)."""
    scenario = daily_scenario(paper33, 48)
    data = snapshot_data(scenario, 0.0)
    opf = build_problem_model("exact", paper33)
    warm, start = [], opf.solve(data.s_fixed[0], data.q_limit[0])
    for i in range(1, 48):
        start = opf.solve(data.s_fixed[i], data.q_limit[i], start)
        assert start.success and start.warm
        warm.append(start)
    cold = [opf.solve(data.s_fixed[i], data.q_limit[i]) for i in range(1, 48)]
    assert all(c.success and not c.warm for c in cold)
    np.testing.assert_allclose([w.objective_kw for w in warm], [c.objective_kw for c in cold], rtol=1e-6)
    warm_its, cold_its = np.mean([w.iterations for w in warm]), np.mean([c.iterations for c in cold])
    assert warm_its < 0.7 * cold_its, (warm_its, cold_its)


def test_sequence_run_records_every_solve(paper33):
    res = run_acopf(daily_scenario(paper33, 12), 0.2, solver="ipopt")
    assert set(res.status) <= set(STATUSES)
    assert list(res.status) == ["ok"] * 12
    assert list(res.extra["warm_start"]) == [False] + [True] * 11
    assert np.all(res.solver.iterations > 0) and np.all(res.solver.solve_ms > 0)
    assert np.all(res.extra["ac_feasible"])
    np.testing.assert_allclose(res.losses_kw, res.solver.objective_kw, atol=1e-3)


def test_snapshot_cli_json_has_solver_fields(capsys):
    assert main(["snapshot", "paper33", "--strategy", "acopf", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("status", "losses_kw", "solve_ms", "iterations", "lower_bound_kw", "relaxation_gap", "fallback", "solver_status"):
        assert out[key] is not None, key
    assert out["status"] == "ok" and out["fallback"] == "none"
    assert out["lower_bound_kw"] <= out["losses_kw"] * (1 + 1e-6)
    assert out["losses_kw"] == pytest.approx(33.23, abs=0.02)


def test_snapshot_cli_reports_infeasible_without_error(capsys):
    code = main(
        [
            "snapshot",
            "paper33",
            "--strategy",
            "acopf",
            "--json",
            "--load-scale",
            "0.2",
            "--der-scale",
            "1",
            "--no-slack-export",
            "--fallback",
            "paper",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "infeasible" and out["fallback"] == "no-action"
    assert out["objective_kw"] is None  # NaN becomes null in JSON


@pytest.mark.parametrize("solver, certified_by", [("auto", "socp"), ("ipopt", "ipopt")])
def test_snapshot_cli_acopf_solver_flag(capsys, solver, certified_by):
    assert main(["snapshot", "paper33", "--strategy", "acopf", "--json", "--acopf-solver", solver]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["certified_by"] == certified_by and (out["iterations"] > 0) == (solver == "ipopt")
    assert out["losses_kw"] == pytest.approx(33.23, abs=0.02)
    assert main(["snapshot", "paper33", "--strategy", "socp", "--acopf-solver", solver]) == 2
    assert "--acopf-solver applies to acopf" in capsys.readouterr().err
