"""The `opendss:` case source and the shipped unbalanced feeders on the command line:
`opfbench pf CASE --json` (its contract and OpenDSS's node voltages), `opfbench cases`,
and bad input — one message naming it, exit 2, before any work."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opfbench.cases.opendss_cases import OPENDSS_NAMES, opendss_copy
from opfbench.cli import main
from tests.support.opendss_feeders import solve
from tests.support.shipped_cases import UNBALANCED

PF_KEYS = {"converged", "losses_kw", "vmin", "vmax", "max_vuf_pct", "node_vm_pu", "band_pu", "iterations", "mismatch"}


def _json(capsys, argv):
    code = main(argv)
    return code, json.loads(capsys.readouterr().out)


def test_pf_json_is_opendss_own_snapshot(capsys):
    code, out = _json(capsys, ["pf", "ieee13", "--json"])
    assert code == 0 and PF_KEYS <= set(out) and out["converged"] and out["operating_point"] == "stored"
    with opendss_copy("ieee13") as master:
        theirs = solve(master)
    assert list(out["node_vm_pu"]) == theirs.node_names  # OpenDSS's node names, in its order
    assert np.array(list(out["node_vm_pu"].values())) == pytest.approx(theirs.vm_pu, abs=1e-6)
    assert out["losses_kw"] == pytest.approx(theirs.losses_kw, rel=1e-4)
    phases = [v for k, v in out["node_vm_pu"].items() if k.rsplit(".", 1)[1] in "123"]
    assert out["vmin"] == pytest.approx(min(phases)) and out["vmax"] == pytest.approx(max(phases))
    assert 1.0 < out["max_vuf_pct"] < 5.0 and out["band_pu"] == [0.95, 1.05]


def test_pf_scaled_point_and_text(capsys):
    assert main(["pf", "ieee37", "--load-scale", "0.5"]) == 0
    text = capsys.readouterr().out
    assert "three-phase" in text and "ANSI C84.1 Range A" in text and "VUF" in text


def test_cases_lists_the_unbalanced_feeders(capsys):
    code, rows = _json(capsys, ["cases", "--json", *UNBALANCED])
    assert code == 0 and [r["case"] for r in rows] == list(UNBALANCED)
    for r in rows:
        assert (r["buses"], r["nodes"], r["loads"], r["ders"]) == UNBALANCED[r["case"]]
    assert set(UNBALANCED) == set(OPENDSS_NAMES)


def _dss(tmp_path, body: str, name: str = "master.dss"):
    file = tmp_path / name
    file.write_text(
        "clear\nnew circuit.t basekv=12.47 bus1=src\n"
        "new line.l1 bus1=src bus2=b2 length=1 units=km r1=0.1 x1=0.2 r0=0.3 x0=0.6\n"
        + body
        + "\nset voltagebases=[12.47]\ncalcv\n"
    )
    return file


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("new load.a bus1=b2 kw=100 kv=12.47 linecode=nope", ["master.dss", "line: 4"]),
        ("new load.a bus1=b2 kw=100 kv=12.47\nnew storage.s1 bus1=b2 kv=12.47", ["Storage.s1", "master.dss", "Storage"]),
        ("new load.a bus1=b2 kw=100 kv=12.47 model=3", ["Load.a", "load model 3", "master.dss"]),
        (
            "new load.a bus1=b2 kw=100 kv=12.47\nnew line.l2 bus1=x1 bus2=x2 length=1 units=km r1=0.1 x1=0.2 r0=0.3 x0=0.6",
            ["islanded", "x1.1", "master.dss"],
        ),
        ("new load.a bus1=b2 kw=100 kv=12.47 rneut=5", ["Load.a", "neutral impedance"]),
    ],
)
def test_bad_opendss_files_exit_2_naming_them(tmp_path, capsys, body, expected):
    file = _dss(tmp_path, body)
    assert main(["pf", f"opendss:{file}"]) == 2
    err = capsys.readouterr().err
    assert all(text in err for text in expected), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["pf", "opendss:/nonexistent/Master.dss"], "not found"),
        (["pf", "opendss:"], "opendss: needs the path"),
        (["pf", "ieee13?der=675:inverter:0.1"], "three-phase"),
        (["fault", "ieee13", "--fault-bus", "671"], "the fault study (a balanced three-phase RMS model) needs a balanced case"),
    ],
)
def test_bad_input_on_unbalanced_cases_exits_2(capsys, argv, expected):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


def test_a_file_without_a_circuit_is_refused(tmp_path, capsys):
    file = tmp_path / "empty.dss"
    file.write_text("clear\n")
    assert main(["pf", f"opendss:{file}"]) == 2
    assert "defines no circuit" in capsys.readouterr().err
