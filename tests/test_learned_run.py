"""Learned rules through `opfbench run` (issue 21): the training optimum in a nested run
folder, the fit written to the run folder, the test period through the engine with the
fitted parameters the tasks received, the perturbed case on the model's fit, resume,
a fitted file used elsewhere, the report's headline, and a Dask cluster whose workers
cannot read the run folder."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.registry.catalog import run_strategy
from opfbench.study.training_checks import training_scenario

TRAIN = "2016-03-01..2016-03-02"
TEST = "2016-03-02T00:00..2016-03-02T06:00"
AFFINE, IEEE = f"learned-affine:train={TRAIN}", f"learned-1547:train={TRAIN},rounds=1"  # rounds: the end-to-end fit
PERTURBED = "paper33?line-z=1.2"
ARGS = ["--k", "0", "--night-modes", "connected", "--forecast", "off", "--quiet"]


def _run(
    out,
    cases=("paper33", PERTURBED),
    strategies=("no-action", "volt-var", AFFINE, IEEE, "acopf"),
    extra=("--workers", "1"),
    period=TEST,
) -> int:
    return main(["run", "--case", *cases, "--strategies", *strategies, "--period", period, *ARGS, *extra, "--out", str(out)])


def test_run_trains_on_the_model_and_tests_out_of_sample(tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(out) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    fitted = manifest["config"]["fitted"]
    assert {(f["case"], f["label"]) for f in fitted} == {(c, s) for c in ("paper33", PERTURBED) for s in (AFFINE, IEEE)}
    refs = {(f["case"], f["label"]): f["ref"] for f in fitted}
    assert refs[(PERTURBED, AFFINE)] == refs[("paper33", AFFINE)]  # the perturbed grid runs the model's fit
    params = json.loads((out / refs[("paper33", AFFINE)]).read_text())
    assert params["case"] == "paper33" and params["train"]["period"] == TRAIN and params["train"]["steps"] == 96
    # the training optimum: a run folder of its own, over the training period, k 0, with the per-DER Q
    reference = json.loads((out / "train" / "reference" / "manifest.json").read_text())
    assert reference["config"]["period"] == TRAIN and reference["config"]["cases"] == ["paper33"]
    assert "acopf" in reference["config"]["strategies"] and (out / "train" / "reference" / "der_q.parquet").exists()
    train = pd.read_csv(out / "train" / "summary.csv")
    assert set(train["case"]) == {"paper33"} and {AFFINE, IEEE, "volt-var", "acopf", "no-action"} == set(train["strategy"])
    assert (train["steps"] == 96).all()
    # the test period: what the tasks ran is the fitted file run directly on the test scenario
    summary = pd.read_csv(out / "summary.csv")
    _, test = training_scenario("paper33", TEST, "20:00-05:00")
    direct = run_strategy(f"learned-affine:params={out / refs[('paper33', AFFINE)]}", test, 0.0)
    row = summary[(summary["case"] == "paper33") & (summary["strategy"] == AFFINE)].iloc[0]
    assert row["steps"] == 24 and row["not_ok_steps"] == 0
    assert np.isclose(row["energy_kwh"], np.sum(direct.losses_kw) * 0.25, rtol=1e-5)
    html = (out / "report.html").read_text()
    assert "How close can a local rule get" in html and "learned/paper33--learned-affine" in html
    # resume: nothing run again, nothing fitted again
    stamp = (out / refs[("paper33", AFFINE)]).stat().st_mtime_ns
    tasks = sorted(p.stat().st_mtime_ns for p in (out / "tasks").glob("*.parquet"))
    assert _run(out) == 0
    assert (out / refs[("paper33", AFFINE)]).stat().st_mtime_ns == stamp
    assert sorted(p.stat().st_mtime_ns for p in (out / "tasks").glob("*.parquet")) == tasks
    # a fitted file edited by hand is not the rule the run fitted: refused on resume, as edited case data are
    fit_file = out / refs[("paper33", AFFINE)]
    text = fit_file.read_text()
    edited = json.loads(text)
    edited["parameters"][0]["a"] += 0.05
    fit_file.write_text(json.dumps(edited))
    assert _run(out) == 2
    assert "the fitted rule is not the one this run fitted and recorded" in capsys.readouterr().err
    assert sorted(p.stat().st_mtime_ns for p in (out / "tasks").glob("*.parquet")) == tasks
    fit_file.write_text(text)
    assert _run(out) == 0 and sorted(p.stat().st_mtime_ns for p in (out / "tasks").glob("*.parquet")) == tasks
    # the fitted file is a rule elsewhere: on the perturbed grid it gives what the run gave there
    other = tmp_path / "other"
    label = f"learned-affine:params={out / refs[('paper33', AFFINE)]}"
    assert _run(other, cases=(PERTURBED,), strategies=("no-action", label)) == 0
    again = pd.read_csv(other / "summary.csv").set_index("strategy")
    first = summary[summary["case"] == PERTURBED].set_index("strategy")
    assert again.loc[label, "energy_kwh"] == first.loc[AFFINE, "energy_kwh"]
    assert not (other / "train").exists()  # nothing to train: the rule was fitted already


def test_a_run_refuses_leaks_before_any_work(tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(out, period="2016-03-01T12:00..2016-03-01T18:00") == 2
    assert "overlaps the test period" in capsys.readouterr().err and not (out / "train").exists()
    other = tmp_path / "other"  # a folder holding another configuration's run: refused before the training
    assert _run(other, cases=("paper33",), strategies=("no-action",)) == 0
    assert _run(other) == 2 and "holds a run of another configuration" in capsys.readouterr().err
    assert not (other / "train").exists()
    two = (AFFINE, "learned-vv:train=2016-02-01..2016-02-02")
    assert _run(out, strategies=("no-action", *two)) == 2
    assert "share one training period" in capsys.readouterr().err


def test_fitted_rules_reach_workers_that_cannot_read_the_run_folder(dask_cluster, tmp_path):
    local, remote = tmp_path / "local", tmp_path / "remote"
    strategies = ("no-action", AFFINE, "acopf")
    assert _run(local, cases=("paper33",), strategies=strategies) == 0
    assert _run(remote, cases=("paper33",), strategies=strategies, extra=("--scheduler", dask_cluster)) == 0
    timing = ["wall_ms", "solver_ms"]
    a = pd.read_parquet(local / "steps.parquet").drop(columns=timing)
    b = pd.read_parquet(remote / "steps.parquet").drop(columns=timing)
    pd.testing.assert_frame_equal(a, b, check_exact=True)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["paper33", "simbench:1-LV-rural3--0-sw"])
def test_a_month_of_training_and_a_week_of_test(case, tmp_path):
    """Every family trained on January and tested on a week of February, nominal and
    perturbed grid: all settle, none leaves its limits, each reduces the losses."""
    train = "2016-01-01..2016-02-01"
    labels = [f"{family}:train={train}" for family in ("learned-affine", "learned-vv", "learned-1547")]
    out = tmp_path / "run"
    argv = ["run", "--case", case, f"{case}?line-z=1.2", "--strategies", "no-action", *labels, "acopf"]
    assert (
        main(
            [*argv, "--period", "2016-02-01..2016-02-08", "--k", "0", "0.4", "--night-modes", "connected"]
            + ["--forecast", "off", "--quiet", "--workers", "2", "--out", str(out)]
        )
        == 0
    )
    summary = pd.read_csv(out / "summary.csv")
    learned = summary[summary["strategy"].isin(labels)]
    assert len(learned) == 2 * 2 * 3 and (learned["not_settled_steps"] == 0).all() and (learned["not_ok_steps"] == 0).all()
    assert (learned["excursion_steps"] == 0).all() and (learned["energy_kwh"] < learned["no_action_kwh"]).all()
    train_summary = pd.read_csv(out / "train" / "summary.csv")
    assert set(labels) <= set(train_summary["strategy"]) and (train_summary["not_settled_steps"] == 0).all()


def test_a_cases_notes_are_said_once_not_again_by_each_nested_training_run(tmp_path, capsys):
    lv = "simbench:1-LV-rural1--0-sw"  # its notes: the taps, the short-circuit data, the phase shift
    assert _run(tmp_path / "run", cases=(lv,), strategies=("no-action", AFFINE, "acopf")) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith(f"note: {lv}")]
    assert len(notes) >= 2 and len(notes) == len(set(notes)), notes
