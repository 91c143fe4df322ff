"""Batching and bookkeeping of the local rules: one `solve_pf_batch` per LFMA step,
divergence (final or intermediate) visible per snapshot, the loss table and the benchmark."""

from __future__ import annotations

import numpy as np
import pytest

import opfbench.strategies.grids as grids
import opfbench.strategies.paper as paper
from opfbench.bench.local import bench_local
from opfbench.bench.paper_day import paper_day_scenario
from opfbench.commands.table import format_table
from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.powerflow import PowerFlowResult, solve_pf_batch
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario
from opfbench.study.loss_table import local_rules, loss_table


def paper33(load_scales: list[float]) -> Scenario:
    net = load_network("paper33")
    return Scenario(net, load_scales, np.tile(0.8 * net.der_rating_mw, (len(load_scales), 1)))


def test_voltage_collapse_is_pf_diverged_per_snapshot() -> None:
    scenario = paper33([1.0, 8.0, 1.2])  # 8 × nominal load has no power-flow solution
    alone = paper.lfma(scenario.take(slice(0, 1)), 0.2)
    for name in ("no-action", "llma", "lfma"):
        res = run_strategy(name, scenario, 0.2)
        assert res.status.tolist() == ["ok", "pf-diverged", "ok"]
        assert np.isnan(res.losses_kw[1]) and np.all(np.isfinite(res.losses_kw[[0, 2]]))
    res = paper.lfma(scenario, 0.2)
    assert res.extra["diverged_step"].tolist() == [0, 1, 0]
    assert res.extra["upstream_disagreements"][1] is None
    assert np.all(paper.lfma_trace(scenario, 0.2).upstream_branch[1] == -1)  # nothing was measured
    np.testing.assert_allclose(res.q_mvar[0], alone.q_mvar[0], atol=1e-9)
    assert res.power_flows.tolist() == [4, 4, 4]


def test_lfma_uses_one_batched_flow_per_step_and_shows_intermediate_divergence(monkeypatch: pytest.MonkeyPatch) -> None:
    scenario = paper33([0.9, 1.0, 1.1])
    clean = paper.lfma_trace(scenario, 0.0)
    calls: list[int] = []

    def flaky(net, s_mw, v0=None):  # the grid "fails" snapshot 1 at the answer to step 3
        calls.append(s_mw.shape[0])
        pf = solve_pf_batch(net, s_mw, v0)
        if len(calls) == 3:
            converged = pf.converged.copy()
            converged[1] = False
            return PowerFlowResult(pf.net, pf.v, converged, pf.iterations)
        return pf

    monkeypatch.setattr(grids, "solve_pf_batch", flaky)  # every answer of the grid
    trace = paper.lfma_trace(scenario, 0.0)
    assert calls == [3, 3, 3, 3]
    assert trace.diverged_step.tolist() == [0, 3, 0]
    assert np.all(trace.rule[1] == paper.STOPPED)  # paper33: every DER bus is a branch node
    np.testing.assert_array_equal(trace.q_final[1], trace.q_step3[1])  # frozen after the failed step
    np.testing.assert_array_equal(trace.q_final[[0, 2]], clean.q_final[[0, 2]])
    calls.clear()
    res = paper.lfma(scenario, 0.0)
    assert res.status.tolist() == ["ok", "pf-diverged", "ok"] and np.isnan(res.losses_kw[1])
    assert res.extra["diverged_step"].tolist() == [0, 3, 0]


@pytest.mark.parametrize("k", [-0.01, 1.01, float("nan"), [0.1, 0.2]])
def test_bad_reserve_raises_input_error(k) -> None:
    scenario = paper33([1.0])
    for name in ("no-action", "llma", "lfma"):
        with pytest.raises(InputError, match="reserve coefficient"):
            run_strategy(name, scenario, k)


def test_loss_table_matches_direct_runs() -> None:
    table = loss_table(ks=(0.0, 0.5), der_scale=0.5)
    assert len(table) == 2 * 2 * len(local_rules()) and set(table["status"]) == {"ok"}
    assert {"no-action", "llma", "lfma", "volt-var", "cosphi-p"} <= set(table["strategy"])
    net = load_network("paper33")
    p_now = 0.5 * net.der_rating_mw
    with_fc = Scenario(net, [1.0], [p_now], [np.minimum(1.2 * p_now, net.der_rating_mw)])  # the table's forecast rule
    row = table.query("forecast and k == 0.0 and strategy == 'lfma'").iloc[0]
    direct = run_strategy("lfma", with_fc, 0.0)
    assert row["losses_kw"] == pytest.approx(direct.losses_kw[0], rel=1e-12)
    assert row["excursion_mvar"] == pytest.approx(direct.excursion_mvar[0], abs=1e-15)
    assert table.query("strategy == 'no-action'")["losses_kw"].nunique() == 1
    text = format_table(table)
    assert "without forecast" in text and "with forecast" in text and "lfma" in text


def test_bench_local_runs_a_small_day() -> None:
    out = bench_local(paper_day_scenario("paper33").take(slice(600, 624)), repeats=1, loop_sample=2)
    assert out["snapshots"] == 24
    rules = out["rules"]
    assert {r["ok"] for r in rules.values()} == {24}
    assert [rules[n]["power_flows_per_snapshot"] for n in ("no-action", "llma", "lfma")] == [1, 1, 4]
    assert rules["lfma"]["energy_losses_kwh"] < rules["no-action"]["energy_losses_kwh"]
    assert out["lfma_one_by_one_ms_extrapolated"] > 0
