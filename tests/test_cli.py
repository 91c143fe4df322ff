"""CLI: `cases` and `pf` contracts, errors on stderr with exit code 2."""

import json
import subprocess
import sys

import numpy as np
import pytest

from opfbench.cli import main
from tests.support.shipped_cases import SHIPPED, UNBALANCED

PF_KEYS = {"case", "converged", "iterations", "losses_kw", "vmin", "vmin_bus", "vmax", "vmax_bus"}


def _json(capsys, argv):
    code = main(argv)
    return code, json.loads(capsys.readouterr().out)


def test_pf_json_contract(capsys):
    code, out = _json(capsys, ["pf", "case33bw", "--json"])
    assert code == 0 and PF_KEYS <= set(out)
    assert out["losses_kw"] == pytest.approx(202.68, abs=0.05) and out["vmin_bus"] == 18


def test_pf_der_scale_applies_to_every_der(capsys):
    """84.26 kW (paper feeder, every DER at 0.8 × rating, Q = 0) and 202.68 kW (no DER
    output) are pandapower's Newton–Raphson losses on the same network: the independent
    source is computed here, not copied."""
    from opfbench.io import load_network
    from tests.support.pandapower_oracle import pandapower_pf

    net = load_network("paper33")
    _, full = _json(capsys, ["pf", "paper33", "--der-scale", "0.8", "--json"])
    _, none = _json(capsys, ["pf", "paper33", "--der-scale", "0", "--json"])
    zero = np.zeros(len(net.ders))
    assert full["losses_kw"] == pytest.approx(pandapower_pf(net, 1.0, 0.8 * net.der_rating_mw, zero)[1], abs=1e-3)
    assert none["losses_kw"] == pytest.approx(pandapower_pf(net, 1.0, zero, zero)[1], abs=1e-3)
    assert full["losses_kw"] == pytest.approx(84.26, abs=0.005)
    assert none["losses_kw"] == pytest.approx(202.68, abs=0.005)


def test_pf_on_a_file_path(capsys, tmp_path):
    from opfbench.cases import _matpower_file

    code, out = _json(capsys, ["pf", str(_matpower_file("case69")), "--json"])
    assert code == 0 and out["vmin_bus"] == 65


def test_pf_non_convergence_is_a_result(capsys):
    code, out = _json(capsys, ["pf", "paper33", "--load-scale", "10", "--json"])
    assert code == 1 and out["converged"] is False and out["losses_kw"] is None


@pytest.mark.parametrize(
    "argv, message",
    [
        (["pf", "nope"], "unknown case 'nope'"),
        (["pf", "paper33", "--der-scale", "1.5"], "--der-scale"),
        (["pf", "paper33", "--load-scale", "nan"], "--load-scale"),
        (["pf"], "case"),
    ],
)
def test_bad_arguments_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_cases_lists_shipped_cases(capsys):
    code, rows = _json(capsys, ["cases", "--json"])
    assert code == 0 and [r["case"] for r in rows] == list(SHIPPED) + list(UNBALANCED)
    for r in rows[len(SHIPPED) :]:
        assert (r["buses"], r["nodes"], r["loads"], r["ders"]) == UNBALANCED[r["case"]]
    for r in rows[: len(SHIPPED)]:
        n_bus, n_branch, in_service, n_der, load_p, load_q, meshed = SHIPPED[r["case"]]
        assert (r["buses"], r["branches"] + r["branches_open"], r["branches"], r["ders"]) == (n_bus, n_branch, in_service, n_der)
        assert r["load_mw"] == pytest.approx(load_p, abs=1e-6) and r["load_mvar"] == pytest.approx(load_q, abs=1e-6)
        assert r["meshed"] == meshed


@pytest.mark.parametrize("strategy", ["no-action", "llma", "lfma", "acopf", "socp"])
def test_every_strategy_runs_on_a_case_without_der(capsys, strategy):
    code, out = _json(capsys, ["snapshot", "case33bw", "--strategy", strategy, "--json"])
    assert code == 0 and out["status"] == "ok" and out["q_mvar"] == {}
    assert out["losses_kw"] == pytest.approx(202.68, abs=0.05)


def test_a_reader_that_closes_the_pipe_stops_the_listing_quietly():
    """`opfbench cases | head -0`: no traceback, the shell's code for a closed pipe (the
    reader is gone before the command has imported its modules, so its first line fails)."""
    proc = subprocess.Popen([sys.executable, "-m", "opfbench", "cases"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141, err
    assert err == ""
