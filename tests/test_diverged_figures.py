"""A step whose power flow did not converge contributes no loss or voltage figure anywhere
(result record, steps table, summary, report, claims); the summary counts such steps and
says over how many steps its averages are. A formulation's lower bound is carried only
where its own point meets the limits, so no step shows a bound above its own losses."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.io import load_network
from opfbench.registry.catalog import run_strategy
from opfbench.report.claims import NA, voltage_band
from opfbench.report.inputs import load_inputs
from opfbench.result import PF_DIVERGED
from opfbench.scenario import Scenario
from opfbench.study.run_tables import partial_summary, summarize

CASE33 = Path(str(resources.files("opfbench.cases") / "matpower" / "case33bw.m"))


def _heavy_case(path: Path, factor: float) -> Path:
    """case33bw with every load (Pd, Qd in kW/kVAr in the file) times `factor`."""

    def scale(m: re.Match) -> str:
        cols = m.group(0).split("\t")
        cols[3], cols[4] = (f"{float(c) * factor:g}" for c in cols[3:5])
        return "\t".join(cols)

    path.write_text(re.sub(r"^\t\d+\t1\t[^\n]*", scale, CASE33.read_text(), flags=re.M))
    return path


def _run(tmp_path: Path, case: Path, period: str, capsys, strategies: tuple[str, ...] = ("no-action",)) -> Path:
    out = tmp_path / "run"
    argv = ["run", "--case", str(case), "--strategies", *strategies, "--k", "0", "--night-modes", "connected"]
    argv += ["--forecast", "off", "--period", period, "--step-minutes", "10", "--workers", "1", "--quiet", "--out", str(out)]
    assert main(argv) == 0, capsys.readouterr().err
    return out


def test_result_record_has_no_voltage_where_the_flow_diverged():
    net = load_network("case33bw")
    heavy = net.with_changes(load_p_mw=net.load_p_mw * 15, load_q_mvar=net.load_q_mvar * 15)
    res = run_strategy("no-action", Scenario(heavy, np.array([1.0, 0.05]), np.zeros((2, 0))), 0.0)
    assert list(res.status) == [PF_DIVERGED, "ok"]
    assert np.isnan(res.losses_kw[0]) and np.all(np.isnan(res.vm[0])) and np.isfinite(res.vm[1]).all()
    assert np.isnan(res.vmin[0]) and np.isnan(res.vmax[0]) and np.isnan(res.voltage_violation()[0])
    out = res.snapshot_json(0)
    assert out["losses_kw"] is None and out["vmin"] is None and out["vmax"] is None


def test_summary_counts_diverged_steps_and_averages_over_the_rest():
    steps = pd.DataFrame(
        {
            "case": "c",
            "strategy": "no-action",
            "k": 0.0,
            "night_mode": "connected",
            "forecast": "off",
            "step_h": 0.5,
            "status": ["ok", PF_DIVERGED, "ok", PF_DIVERGED],
            "losses_kw": [10.0, np.nan, 30.0, np.nan],
            "vmin_pu": [0.95, np.nan, 0.93, np.nan],
            "vmax_pu": [1.0, np.nan, 1.0, np.nan],
            "max_vuf_pct": np.nan,  # a balanced case: no unbalance factor
            "voltage_violation_pu": [0.0, np.nan, 0.0, np.nan],
            "excursion_mvar": 0.0,
            "lower_bound_kw": np.nan,
            "wall_ms": 1.0,
            "solver_ms": np.nan,
            "certified_by": "",
            "curtailed_kw": [0.0, np.nan, 0.0, np.nan],
            "frontier_kw": [8.0, np.nan, 25.0, np.nan],
            "frontier_bound_kw": [8.0, np.nan, 25.0, np.nan],
            "frontier_curtails": False,
            "frontier_limit": "reserve",
        }
    )
    key = ("c", "no-action", 0.0, "connected", "off")
    row = summarize([partial_summary(steps)], [key]).iloc[0]
    assert (row.steps, row.pf_converged_steps, row.pf_diverged_steps, row.not_ok_steps) == (4, 2, 2, 2)
    assert row.avg_loss_kw == pytest.approx(20.0)  # over the two converged steps, not 40 kWh / 2 h
    assert np.isnan(row.energy_kwh) and np.isnan(row.savings_pct)  # the period's energy is not known
    assert (row.vmin_pu, row.vmax_pu, row.voltage_violation_steps) == (0.93, 1.0, 0)
    converged = summarize([partial_summary(steps[steps.status == "ok"])], [key]).iloc[0]
    assert converged.energy_kwh == pytest.approx(20.0) and converged.pf_diverged_steps == 0


def test_a_run_where_every_step_diverges_reports_no_figure(tmp_path, capsys):
    heavy = _heavy_case(tmp_path / "heavy.m", 15)
    out = _run(tmp_path, heavy, "2016-06-28T10:00..2016-06-28T12:00", capsys, ("no-action", "llma"))
    steps = pd.read_parquet(out / "steps.parquet")
    assert (steps.status == PF_DIVERGED).all()
    assert steps[["losses_kw", "vmin_pu", "vmax_pu", "voltage_violation_pu"]].isna().all().all()
    row = pd.read_csv(out / "summary.csv").iloc[0]
    assert (row.steps, row.pf_converged_steps, row.pf_diverged_steps, row.voltage_violation_steps) == (12, 0, 12, 0)
    for column in ("avg_loss_kw", "energy_kwh", "savings_pct", "vmin_pu", "vmax_pu"):
        assert np.isnan(row[column]), column  # not 0 kWh, not |V| from 5e-7 to 4e4 p.u.
    html = (out / "report.html").read_text()
    assert (
        "2 configuration(s) have steps without a loss or voltage figure (pf-diverged, the power flow did not converge: 24 steps)"
        in html
    )
    claim = voltage_band(load_inputs(out))
    assert claim.verdict == NA and claim.reason == "no local-rule step has a voltage figure"


def test_a_partly_diverged_run_averages_over_the_converged_steps(tmp_path, capsys):
    out = _run(tmp_path, _heavy_case(tmp_path / "heavy6.m", 6), "2016-06-28T00:00..2016-06-28T12:00", capsys)
    steps = pd.read_parquet(out / "steps.parquet")
    row = pd.read_csv(out / "summary.csv").iloc[0]
    converged = steps[steps.status != PF_DIVERGED]
    assert 0 < row.pf_diverged_steps < row.steps and row.pf_converged_steps == len(converged)
    assert row.avg_loss_kw == pytest.approx(converged.losses_kw.mean(), rel=1e-6)
    assert np.isnan(row.energy_kwh)
    assert row.vmin_pu == pytest.approx(converged.vmin_pu.min(), rel=1e-5) and 0.3 < row.vmin_pu < row.vmax_pu <= 1.0
    assert row.voltage_violation_steps == (converged.voltage_violation_pu > 1e-6).sum()


def test_an_infeasible_step_carries_no_bound_above_its_losses(paper33):
    # surplus PV the slack may not export: the relaxation "burns" it (bound ≈ the surplus),
    # the point applied is no action, which exports — it is outside the problem the bound is for
    # (solver "ipopt" solves every step's relaxation; by default the interval bounds prove
    # the step infeasible first and the relaxation is not solved there)
    res = run_strategy("acopf-paper", Scenario.snapshot(paper33, 0.1, 1.0), 0.0, solver="ipopt")
    assert res.status[0] == "infeasible" and not res.extra["ac_feasible"][0]
    assert np.isnan(res.lower_bound_kw[0]) and res.snapshot_json()["lower_bound_kw"] is None
    assert res.extra["relaxation_bound_kw"][0] > res.losses_kw[0]  # the relaxation's value, kept as a diagnostic
    proven = run_strategy("acopf-paper", Scenario.snapshot(paper33, 0.1, 1.0), 0.0)
    assert proven.status[0] == "infeasible" and proven.losses_kw[0] == res.losses_kw[0]
    assert proven.snapshot_json()["lower_bound_kw"] is None and proven.snapshot_json()["relaxation_bound_kw"] is None
    ok = run_strategy("acopf", Scenario.snapshot(paper33, 0.1, 1.0), 0.0)  # the slack may export: feasible
    assert ok.status[0] == "ok" and ok.lower_bound_kw[0] <= ok.losses_kw[0] * (1 + 1e-6)


def test_checkpoints_without_the_counts_are_recomputed_not_summed(tmp_path, capsys):
    """Partial sums rewritten without the counts (as an older version wrote them) are not
    this task's checkpoint: the resumed run recomputes the task, with a note, and its
    summary is the uninterrupted run's."""
    out = _run(tmp_path, _heavy_case(tmp_path / "heavy6.m", 6), "2016-06-28T10:00..2016-06-28T10:30", capsys)
    before = pd.read_csv(out / "summary.csv")
    for path in (out / "tasks").glob("*.summary.parquet"):
        partial = pd.read_parquet(path)
        partial.drop(columns=["pf_converged_steps", "measured_hours"]).to_parquet(path, index=False)
    argv = ["run", "--case", str(tmp_path / "heavy6.m"), "--strategies", "no-action", "--k", "0", "--night-modes"]
    argv += ["connected", "--forecast", "off", "--period", "2016-06-28T10:00..2016-06-28T10:30", "--step-minutes", "10"]
    assert main([*argv, "--workers", "1", "--quiet", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "is partly missing" in err or "was not written as this task's checkpoint" in err, err
    pd.testing.assert_frame_equal(before.drop(columns=["wall_s"]), pd.read_csv(out / "summary.csv").drop(columns=["wall_s"]))
    assert not (out / ".lock").exists()
