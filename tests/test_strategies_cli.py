"""`opfbench snapshot CASE --strategy LABEL` and `opfbench strategies` through `opfbench.cli.main`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from opfbench.cli import main

KEYS = {"strategy", "k", "status", "losses_kw", "q_mvar", "vmin", "vmax", "power_flows", "excursion_mvar", "wall_ms"}


def snapshot_json(capsys: pytest.CaptureFixture, *args: str) -> dict:
    assert main(["snapshot", "paper33", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("strategy,flows", [("no-action", 1), ("llma", 1), ("lfma", 4)])
def test_json_contract(capsys: pytest.CaptureFixture, strategy: str, flows: int) -> None:
    out = snapshot_json(capsys, "--strategy", strategy, "--k", "0.2")
    assert KEYS <= set(out)
    assert out["strategy"] == strategy and out["k"] == 0.2 and out["status"] == "ok"
    assert out["power_flows"] == flows
    assert out["q_mvar"].keys() == {"PV-10", "PV-16", "PV-19", "PV-29", "DFIG-27"}  # the paper's DER, by name
    assert out["der_bus"] == {"PV-10": 10, "PV-16": 16, "PV-19": 19, "PV-29": 29, "DFIG-27": 27}
    assert 0.9 < out["vmin"] <= out["vmax"] <= 1.1 and out["losses_kw"] > 0
    assert out["excursion_mvar"] == 0.0
    if strategy == "no-action":
        assert all(q == 0.0 for q in out["q_mvar"].values())
    if strategy == "lfma":
        assert out["upstream_disagreements"] == [] and out["diverged_step"] == 0


def test_k_one_equals_no_action(capsys: pytest.CaptureFixture) -> None:
    none = snapshot_json(capsys, "--strategy", "no-action")
    for strategy in ("llma", "lfma"):
        out = snapshot_json(capsys, "--strategy", strategy, "--k", "1")
        assert all(q == 0.0 for q in out["q_mvar"].values())
        assert out["losses_kw"] == pytest.approx(none["losses_kw"], abs=1e-6)  # LFMA flows start warm


def test_forecast_excursion_and_safe(capsys: pytest.CaptureFixture) -> None:
    # P^C = 0.3·P̄, P^F = 0.5·P̄ (P̄ = 0.6 MW): the PV limit rises from 0.75·0.18 = 0.135 to
    # 0.75·0.3 = 0.225 MVAr; the DFIG (bus 27) stays at 1.0·P̄ = 0.6 MVAr for p ≤ 0.4.
    args = ["--strategy", "lfma", "--der-scale", "0.3", "--forecast-der-scale", "0.5"]
    loose, safe = snapshot_json(capsys, *args), snapshot_json(capsys, *args, "--safe")
    plain = snapshot_json(capsys, "--strategy", "lfma", "--der-scale", "0.3")
    assert loose["excursion_mvar"] > 0 and safe["excursion_mvar"] == 0.0
    assert safe["q_mvar"] == plain["q_mvar"]  # here the safe cap is exactly the plain limit (k = 0)
    pv = ("PV-10", "PV-16", "PV-19", "PV-29")
    assert all(abs(loose["q_mvar"][b]) <= 0.225 + 1e-12 for b in pv)
    assert all(abs(safe["q_mvar"][b]) <= 0.135 + 1e-12 for b in pv)
    assert any(loose["q_mvar"][b] > 0.135 + 1e-6 for b in pv)


def test_text_output_shows_lfma_diagnostics(capsys: pytest.CaptureFixture) -> None:
    assert main(["snapshot", "paper33", "--strategy", "lfma"]) == 0
    out = capsys.readouterr().out
    assert "lfma" in out and "power flows   4" in out and "upstream disagreements: []" in out
    assert main(["snapshot", "paper33-meshed", "--strategy", "lfma", "--json"]) == 0
    buses = json.loads(capsys.readouterr().out)["upstream_disagreements"]
    assert main(["snapshot", "paper33-meshed", "--strategy", "lfma"]) == 0
    assert f"upstream disagreements: {buses}" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args,message",
    [
        (["--strategy", "llma", "--k", "1.5"], "reserve coefficient k must lie in [0, 1]"),
        (["--strategy", "no-action", "--k", "2"], "reserve coefficient k must lie in [0, 1]"),
        (["--strategy", "lfma", "--k", "-0.1"], "--k"),
        (["--strategy", "lfma", "--k", "nan"], "--k"),
        (["--strategy", "lfma", "--der-scale", "1.5"], "argument --der-scale: must lie in [0, 1], got 1.5"),
        (["--strategy", "llma", "--fallback", "chain"], "--fallback"),
        (["--strategy", "teleport"], "unknown strategy 'teleport'"),
        (["--strategy", "volt-var:curve=c"], "option curve: 'c' is not one of a, b"),
        (["--strategy", "volt-var:v=1.0/0.9,q=0/0"], "the curve's v values must increase"),
        (["--strategy", "const-pf:pf=1.5"], "a power factor must lie in (0, 1]"),
        (["--strategy", "volt-var", "--fallback", "paper"], "--fallback applies to acopf, not to volt-var"),
        (["--strategy", "llma", "--plugin", "no_such_plugin_module"], "plugin no_such_plugin_module: cannot import it"),
    ],
)
def test_bad_arguments_exit_2(capsys: pytest.CaptureFixture, args: list[str], message: str) -> None:
    assert main(["snapshot", "paper33", *args]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.out == ""


def test_unknown_case_exit_2(capsys: pytest.CaptureFixture) -> None:
    assert main(["snapshot", "nowhere33", "--strategy", "lfma"]) == 2
    assert "unknown case" in capsys.readouterr().err


def test_a_label_with_options_runs_in_snapshot(capsys: pytest.CaptureFixture) -> None:
    out = snapshot_json(capsys, "--strategy", "volt-var:curve=b,step_factor=0.50", "--k", "0.2")
    assert out["strategy"] == "volt-var" and out["status"] == "ok" and out["power_flows"] > 1
    assert out["residual_mvar"] <= 1e-7  # the closed loop settled
    curve_a = snapshot_json(capsys, "--strategy", "volt-var:curve=a", "--k", "0.2")
    assert curve_a["strategy"] == "volt-var:curve=a" and curve_a["q_mvar"] != out["q_mvar"]


@pytest.mark.usefixtures("isolated_registry")
def test_strategies_lists_every_strategy_with_its_options(capsys: pytest.CaptureFixture) -> None:
    assert main(["strategies", "--json"]) == 0
    entries = {e["name"]: e for e in json.loads(capsys.readouterr().out)}
    assert {"no-action", "llma", "lfma", "volt-var", "watt-var", "const-pf", "cosphi-p", "q-u", "acopf", "socp"} <= set(entries)
    vv = entries["volt-var"]
    assert vv["kind"] == "local" and vv["reads"] == ["v"] and vv["closed_loop"] and vv["uses_forecast"]
    curve = next(o for o in vv["options"] if o["name"] == "curve")
    assert curve == {"name": "curve", "type": "choice", "default": "b", "help": curve["help"], "allowed": ["a", "b"]}
    solver = next(o for o in entries["acopf"]["options"] if o["name"] == "solver")
    assert (
        solver["default_from"] == "acopf_solver" and entries["socp"]["lower_bound"] and entries["acopf"]["kind"] == "formulation"
    )
    example = str(Path(__file__).resolve().parents[1] / "docs" / "custom_rule.py")
    assert main(["strategies", "--plugin", example]) == 0
    text = capsys.readouterr().out
    assert f"droop  [plugin {example}]" in text and "gain=5  number" in text
