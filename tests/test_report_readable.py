"""What a reader sees: table headings with units, the share plot's axis chosen by what the
case has, the committed real-grid year and learned-rule studies in the report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from opfbench.registry.references import DEFAULT_RUN
from opfbench.report import plots, sections, tables
from opfbench.report.inputs import DOCS_FIELD_YEAR, DOCS_LEARNED, Inputs, load_study
from opfbench.report.page import heading, table_html
from opfbench.report.tables import leaderboard

PRICE = (0.2, "EUR", "test")


@pytest.mark.parametrize(
    ("column", "shown"),
    [
        ("energy_kwh", "energy (kWh)"),
        ("opf_share_pct", "OPF share (%)"),
        ("max_violation_pu", "max violation (p.u.)"),
        ("not_settled_steps", "not settled steps"),
        ("recovery_added_ms", "recovery added (ms)"),
        ("case", "case"),
        ("certified optimal %", "certified optimal %"),
    ],
)
def test_headings_name_the_unit(column, shown):
    assert heading(column) == shown


def test_a_table_keeps_the_data_column_as_the_headings_title():
    html = table_html(pd.DataFrame({"case": ["paper33"], "energy_kwh": [1.5]}))
    assert '<th class="num" title="energy_kwh">energy (kWh)</th>' in html
    assert "<th>case</th>" in html


def test_a_voltage_error_in_pu_keeps_its_digits():
    html = table_html(pd.DataFrame({"strategy": ["lindist3flow"], "max |V| error p.u.": [1.86e-3]}))
    assert ">0.0019<" in html


def _board(violations: float, recovery: float | None) -> pd.DataFrame:
    rows = []
    for k in (0.0, 0.4):
        for strategy, energy in (("no-action", 100.0), ("lfma", 90.0 + k), ("acopf", 80.0 + k)):
            rows.append(
                {
                    "case": "grid",
                    "strategy": strategy,
                    "k": k,
                    "night_mode": "connected",
                    "forecast": "off",
                    "energy_kwh": energy,
                    "no_action_kwh": 100.0,
                    "voltage_violation_min": violations if strategy == "lfma" else 0.0,
                    "not_ok_steps": 0,
                }
            )
    summary = pd.DataFrame(rows)
    rec = None
    if recovery is not None:
        rec = pd.DataFrame(
            [
                {"case": "grid", "strategy": s, "k": k, "forecast": "off", "variant": "reference", "added_ms": recovery}
                for s in ("lfma", "acopf")
                for k in (0.0, 0.4)
            ]
        )
    return leaderboard(summary, recovery=rec)


@pytest.mark.parametrize(
    ("violations", "recovery", "ids"),
    [
        (0.0, None, ["share-k-0"]),
        (15.0, None, ["share-k-0"]),  # compliance is the frontier figure's axis
        (0.0, -3.0, ["share-recovery-added-ms-0"]),
        (15.0, -3.0, ["share-recovery-added-ms-0"]),
    ],
)
def test_the_share_is_plotted_against_what_the_case_has(violations, recovery, ids):
    assert [p.id for p in plots.share_vs_costs(_board(violations, recovery))] == ids


def test_the_headline_figure_cuts_a_share_far_below_no_action():
    board = pd.DataFrame(
        {
            "case": ["grid"] * 3,
            "k": [0.0] * 3,
            "strategy": ["no-action", "lfma", "learned-affine:train=2016-01-01..2016-10-01,rounds=3"],
            "train_share_eq_pct": [0.0, -2500.0, 95.0],
            "test_share_eq_pct": [0.0, -3000.0, 97.0],
        }
    )
    (plot,) = plots.how_close(board, " — grid")
    figure = json.loads(plot.json)
    assert figure["layout"]["yaxis"]["range"][0] == plots.SHARE_FLOOR_PCT
    assert "axis cut" in plot.title
    assert "learned-affine:rounds=3" in figure["data"][0]["x"][1]  # the training period is the run's, said beside
    (uncut,) = plots.how_close(board.assign(train_share_eq_pct=[0.0, -20.0, 95.0], test_share_eq_pct=[0.0, -30.0, 97.0]))
    assert "axis cut" not in uncut.title and "range" not in json.loads(uncut.json)["layout"].get("yaxis", {})
    layout = json.loads(plot.json)["layout"]  # its long title: wrapped clear of Plotly's toolbar, escaped
    lines = layout["title"]["text"].split("<br>")
    assert len(lines) > 1 and max(map(len, lines)) <= plots.TITLE_CHARS and layout["margin"]["t"] > 50
    assert plots.wrapped_title("a <b> & c " * 12)[0].count("&lt;b&gt;") == 12
    assert plots.wrapped_title("short") == ("short", 1)


def _field_inputs() -> Inputs:
    return Inputs(
        run_dir=Path(),
        field_summary=pd.read_csv(DOCS_FIELD_YEAR / "summary.csv"),
        field_manifest=json.loads((DOCS_FIELD_YEAR / "manifest.json").read_text()),
    )


def test_the_committed_real_grid_year_holds_every_strategy_and_is_shown():
    inputs = _field_inputs()
    s = inputs.field_summary
    assert s is not None and (s["steps"] == 35136).all()
    cases = {"simbench:1-MV-rural--0-sw", "simbench:1-LV-rural3--0-sw"}
    assert set(s["case"]) == cases and set(s["k"]) == {0.0, 0.4}
    assert set(s["night_mode"]) == {"connected", "disconnected"}
    assert set(s["strategy"]) == set(DEFAULT_RUN)
    assert (s["pf_diverged_steps"] == 0).all() and (s["not_settled_steps"] == 0).all()
    acopf = s[s["strategy"] == "acopf"]
    assert np.allclose(acopf["certified_share"], 1.0)
    sec = sections.field_year(inputs, PRICE)
    html = " ".join(b.html for b in sec.blocks if b.kind == "table")
    assert all(c in html for c in cases) and "Leaderboard over the year, PV disconnected" in " ".join(b.text for b in sec.blocks)
    meta = dict(next(b for b in sec.blocks if b.kind == "meta").items)
    assert "MB" in meta["peak memory"] and "worker" in meta["wall time"]
    missing = sections.field_year(Inputs(run_dir=Path(), missing={"real grids' year run": "opfbench run ..."}), PRICE)
    assert [b.kind for b in missing.blocks] == ["missing"]


def test_the_headline_shows_the_committed_learned_studies_when_the_run_trained_none():
    studies = [load_study(f) for f in sorted(DOCS_LEARNED.glob("*/"))]
    assert {s.run_dir.name for s in studies} == {"paper33", "1-LV-rural3", "1-MV-rural"}
    for study in studies:
        assert study.train_summary is not None and len(study.learned) == 6  # 3 families, plain and end to end
        learned = study.summary[study.summary["strategy"].str.startswith("learned-")]
        assert (learned["not_settled_steps"] == 0).all()
        if study.frontier is not None:  # re-run with the frontier: its shares at equal compliance
            assert tables.at_equal_compliance(study.summary)
            assert learned["share_eq_pct"].notna().any() and not (learned["share_eq_pct"] > 100.0).any()
            assert not (learned["gap_eq_kwh"] < 0.0).any()
    with_frontier = [s for s in studies if s.frontier is not None]
    assert with_frontier
    run = studies[0]
    inputs = Inputs(run_dir=Path(), summary=run.summary, manifest=run.manifest, studies=studies)
    sec = sections.how_close(inputs)
    headings = [b.text for b in sec.blocks if b.kind == "heading"]
    assert headings == [f"A committed study: {s.run_dir.name}" for s in studies]
    # a share figure for the run and each study, and a frontier figure per case and k of each study that has one
    frontiers = sum(s.summary.groupby(["case", "k"]).ngroups for s in with_frontier)
    assert sum(b.kind == "plot" for b in sec.blocks) == 1 + len(studies) + frontiers


def test_a_case_without_any_optimum_is_said_in_words():
    rows = [
        {"case": c, "strategy": s, "k": 0.0, "night_mode": "connected", "forecast": "off", "energy_kwh": e}
        | {"no_action_kwh": 10.0, "steps": 4, "not_ok_steps": bad, "voltage_violation_min": 0.0}
        for c, bad in (("lv5", 4), ("ok", 1))
        for s, e in (("no-action", 10.0), ("lfma", 9.0), ("acopf", float("nan") if bad == 4 else 8.0))
    ]
    summary = pd.DataFrame(rows)
    notes = [b.text for b in sections.grids(Inputs(run_dir=Path(), summary=summary)).blocks if b.kind == "note"]
    assert [n for n in notes if "no optimum" in n] == [
        "lv5, k=0: the AC OPF has no optimum at any of the 4 steps (infeasible or failed: see the convergence "
        "section), so there is no reference and no share of its loss reduction (—)."
    ]


def test_an_optimum_that_fell_back_but_reduced_losses_is_not_called_missing():
    rows = [
        {"case": "g", "strategy": s, "k": 0.0, "night_mode": "connected", "forecast": "off", "energy_kwh": e}
        | {"no_action_kwh": 10.0, "steps": 4, "not_ok_steps": 4 if s == "acopf" else 0}
        for s, e in (("no-action", 10.0), ("acopf", 8.0))  # every step fallback-cold: still an optimum
    ]
    assert tables.without_optimum(pd.DataFrame(rows)) == []


def test_the_frontier_figure_draws_the_frontier_as_a_staircase_and_every_configuration_as_a_point():
    board = pd.DataFrame(
        {
            "case": ["grid"] * 3,
            "k": [0.0] * 3,
            "strategy": ["acopf", "lfma", "volt-watt"],
            "cost_kwh": [100.0, 103.0, 104.0],
            "max_violation_pu": [0.0, 0.004, 0.0],
            "voltage_violation_min": [0.0, 75.0, 0.0],
            "gap_eq_kwh": [0.0, 4.0, 4.0],
            "share_eq_pct": [100.0, 60.0, 55.0],
            "frontier_curtails": [False, False, True],
        }
    )
    eps = [0.0, 0.0025, 0.005, 0.01, 0.02, 0.05, np.inf]
    frontier = pd.DataFrame(
        {
            "case": "grid",
            "k": 0.0,
            "night_mode": "connected",
            "curtail": [False] * 7 + [True],
            "eps_pu": eps + [0.0],
            "energy_kwh": [100.0, 99.5, 99.0, 98.8, 98.8, 98.8, 98.8, 99.0],
        }
    )
    (plot,) = plots.frontier_vs_compliance(board, frontier)
    data = json.loads(plot.json)["data"]
    line, points = data[0], data[1:]
    assert line["line"]["shape"] == "vh" and len(line["x"]) == 7 and line["x"][-1] > 0.05  # ∞ drawn at the right edge
    assert [p["name"] for p in points] == ["lfma", "volt-watt", "acopf"] or {p["name"] for p in points} == {
        "acopf",
        "lfma",
        "volt-watt",
    }
    symbols = {p["name"]: p["marker"]["symbol"] for p in points}
    assert symbols["volt-watt"] == "diamond" and symbols["lfma"] == "circle"
    assert plots.frontier_vs_compliance(board, None) == []


def test_a_leaderboard_without_a_share_says_why():
    def rows(case: str, energies: dict[str, float]) -> list[dict]:
        return [
            {"case": case, "strategy": s, "k": 0.0, "night_mode": "connected", "forecast": "off", "energy_kwh": e}
            | {"no_action_kwh": 10.0, "steps": 4, "not_ok_steps": 0, "voltage_violation_min": 0.0}
            for s, e in energies.items()
        ]

    summary = pd.DataFrame(
        rows("no-opf", {"no-action": 10.0, "lfma": 9.0})
        + rows("saves-nothing", {"no-action": 10.0, "lfma": 9.0, "acopf": 10.0})
        + rows("fine", {"no-action": 10.0, "lfma": 9.0, "acopf": 8.0})
    )
    notes = [b.text for b in sections.grids(Inputs(run_dir=Path(), summary=summary)).blocks if b.kind == "note"]
    assert [n for n in notes if "no loss-only share" in n] == [
        "no-opf, k=0: no loss-only share of the AC OPF's loss reduction (—): the run has no acopf configuration (add it to "
        "--strategies: the share is of its loss reduction).",
        "saves-nothing, k=0: no loss-only share of the AC OPF's loss reduction (—): the acopf saves no loss here (10 kWh "
        "against 10 kWh with no action).",
    ]
