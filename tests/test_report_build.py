"""The HTML report: built from contract files, every section present, missing inputs named,
claims computed (a changed table flips a verdict), input strings escaped, CLI command."""

from __future__ import annotations

import dataclasses

import pytest

from opfbench.cli import main
from opfbench.report import build_html, write_report
from opfbench.report.claims import FAILS, HOLDS, NA, claims
from opfbench.report.inputs import load_inputs
from tests.support.report_folders import write_fault, write_run

SECTIONS = ("claims", "metadata", "losses", "convergence", "year", "night", "gap", "voltage", "forecasting", "fault")
EVIL = "<img src=x onerror=alert(1)>.m"


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    write_run(root / "year", detail=False, period="year")
    return write_run(root / "run"), write_fault(root / "fault")


def _verdicts(inputs) -> dict[str, str]:
    return {c.claim: c.verdict for c in claims(inputs)}


def test_full_report_has_every_section_and_no_missing_input(folders):
    run, fault = folders
    html = build_html(load_inputs(run, fault_dir=fault, year_dir=run.parent / "year"))
    for section in SECTIONS:
        assert f'<section id="{section}" class="report-section">' in html
    assert "Not available" not in html and "could not be built" not in html
    year = html[html.index('id="year"') : html.index('id="night"')]
    assert "321 MB (main process), 654 MB (largest worker process)" in year and "Energy losses over the year" in year
    assert html.count("<script>") == 2  # plotly.js once, the drawing loop once
    # one JSON element per figure, and the template they share once
    assert html.count('class="plot"') + 1 == html.count('type="application/json"') and html.count('class="plot"') >= 10
    assert html.count('id="plot-template"') == 1 and html.count("plotly_white") == 0
    assert "<script src=" not in html and "<link" not in html


def test_missing_inputs_name_the_command(tmp_path):
    out = write_report(tmp_path, forecast_dir=tmp_path, out=tmp_path / "r.html", year_dir=tmp_path)
    html = out.read_text()
    for section in SECTIONS:
        assert f'id="{section}"' in html
    assert f"opfbench run --out {tmp_path}" in html
    assert "opfbench forecast --dataset pv --out DIR" in html and "opfbench fault CASE --out DIR" in html
    assert "opfbench run --period year --out reports/year" in html
    assert set(_verdicts(load_inputs(tmp_path, forecast_dir=tmp_path)).values()) == {NA}


def test_claim_verdicts_follow_the_tables(folders):
    run, fault = folders
    inputs = load_inputs(run, fault_dir=fault)
    before = _verdicts(inputs)
    ranking = "LFMA < LLMA < no action at every k"
    llma = "LLMA adds 1–20 ms to the recovery time (vs no action)"
    assert before[ranking] == HOLDS and before[llma] == HOLDS

    summary = inputs.summary.copy()
    row = (summary.strategy == "lfma") & (summary.k == 0.4) & (summary.night_mode == "connected") & (summary.forecast == "off")
    summary.loc[row, "energy_kwh"] = (
        summary.loc[(summary.strategy == "llma") & (summary.k == 0.4) & (summary.night_mode == "connected"), "energy_kwh"].iloc[0]
        + 1.0
    )
    fault_table = inputs.fault.copy()
    fault_table.loc[fault_table.strategy == "llma", "recovery_ms"] += 25.0
    after = _verdicts(dataclasses.replace(inputs, summary=summary, fault=fault_table))
    assert after[ranking] == FAILS and after[llma] == FAILS
    assert after["Wavelet-CNN-LSTM is the best forecaster"] == before["Wavelet-CNN-LSTM is the best forecaster"]


def test_input_strings_are_escaped(tmp_path):
    run = write_run(tmp_path / EVIL, case=EVIL, detail=False)
    html = build_html(load_inputs(run))
    assert "<img" not in html
    assert "&lt;img src=x onerror=alert(1)&gt;.m" in html


def test_report_command_rebuilds_the_page(folders, tmp_path, capsys):
    run, fault = folders
    out = tmp_path / "report.html"
    year = run.parent / "year"
    assert (
        main(["report", str(run), "--fault-dir", str(fault), "--year-dir", str(year), "--out", str(out), "--price", "0.5"]) == 0
    )
    html = out.read_text()
    assert "0.5 EUR/kWh — given with --price" in html
    again = write_report(run, fault_dir=fault, out=tmp_path / "again.html", price=0.5, year_dir=year)
    assert again.read_text() == html  # rebuilding from the same files gives the same page
    assert main(["report", str(tmp_path / "absent")]) == 2
    assert "opfbench run --out" in capsys.readouterr().err
    assert main(["report", str(run), "--year-dir", str(run)]) == 2  # a paper-day run is not a year run
    assert "holds no finished year run" in capsys.readouterr().err
    assert main(["report", str(run), "--year-dir", str(year), "--out", str(tmp_path / "y.html")]) == 0
    assert f"{year} (created" in (tmp_path / "y.html").read_text()


def test_a_der_keeps_its_colour_in_every_panel(folders):
    """The per-DER Q figure has one panel per strategy and the legend only in the first:
    each DER must be drawn in the same colour in all of them."""
    import json

    from opfbench.report.plots import der_q_day

    run, _ = folders
    fig = json.loads(der_q_day(load_inputs(run).der_q)[0].json)
    colour = {}
    for trace in fig["data"]:
        colour.setdefault(trace["legendgroup"], set()).add(trace["line"]["color"])
    assert len(colour) >= 2 and all(len(c) == 1 for c in colour.values())
    assert len({next(iter(c)) for c in colour.values()}) == len(colour)  # and DERs differ


def test_year_convergence_leaves_the_socp_uncertified(folders):
    """The socp point is the bound's, never a certified AC optimum: "—", not 0 %."""
    from opfbench.report.tables import convergence_summary

    run, _ = folders
    inputs = load_inputs(run)
    table = convergence_summary(inputs.summary, inputs.kinds()).set_index("strategy")["certified optimal %"]
    assert table.loc["socp"].isna().all() and table.loc["acopf"].notna().all()
