"""Every bad input gets one clear error naming it (exit code 2 on the command line) —
never a traceback, never a silently wrong result. One test per class of input."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.errors import DataError, InputError
from opfbench.forecasting.outputs import load_forecast
from opfbench.io import load_network
from opfbench.io.sources import formats
from opfbench.scenario import Scenario
from tests.support.matpower_texts import TINY_CASE, with_entry

# ----- case files ------------------------------------------------------------------------
_BUS1 = "\t1\t3\t0\t0\t0\t0\t1\t1\t0\t12.66"
_PF_LINES = "pf = {};\nmpc.bus(:, QD) = mpc.bus(:, PD) * sin(acos(pf));\n"
BAD_CASES = {
    "fractional bus id": (
        TINY_CASE.replace("\t3\t1\t90", "\t2.9\t1\t90"),
        "mpc.bus row 3, column 1 (BUS_I): 2.9 is not an integer",
    ),
    "fractional branch end": (TINY_CASE.replace("\t2\t3\t0.4930", "\t2\t3.5\t0.4930"), "mpc.branch row 2, column 2 (T_BUS): 3.5"),
    "negative resistance": (TINY_CASE.replace("0.4930", "-0.4930"), "mpc.branch row 2 (2-3): negative resistance BR_R = -0.493"),
    "infinite baseMVA": (
        TINY_CASE.replace("mpc.baseMVA = 10;", "mpc.baseMVA = Inf;"),
        "mpc.baseMVA must be a finite positive number, got inf",
    ),
    "baseKV 0 with ohm conversion": (
        TINY_CASE.replace(_BUS1, _BUS1[:-5] + "0"),
        "line 24: Vbase from mpc.bus row 1 BASE_KV = 0 kV",
    ),
    "power factor 2": (TINY_CASE + _PF_LINES.format(2), "line 28: power factor pf = 2 must lie in (0, 1]"),
    "power factor 0": (TINY_CASE + _PF_LINES.format(0), "line 28: power factor pf = 0 must lie in (0, 1]"),
    "Vmin above Vmax": (
        TINY_CASE.replace("12.66\t1\t1.1\t0.9;\n\t3", "12.66\t1\t0.9\t1.1;\n\t3"),
        "mpc.bus row 2 (bus 2): VMIN 1.1 > VMAX 0.9",
    ),
}


def _cli(capsys: pytest.CaptureFixture, argv: list[str]) -> tuple[int, str]:
    code = main(argv)
    err = capsys.readouterr().err
    return code, err


_CASE33 = (Path(str(resources.files("opfbench.cases") / "matpower" / "case33bw.m"))).read_text()
# (file text, what the message must say) — each refused by pf and by the local rules alike
BAD_VALUES = {
    "duplicated bus 7": (with_entry(_CASE33, "bus", 8, 1, "7"), "mpc.bus row 8 lists bus 7 again (first at row 7)"),
    "bus number 2^63": (
        with_entry(_CASE33, "bus", 2, 1, "9223372036854775808"),
        "mpc.bus row 2, column 1 (BUS_I): bus number 9.22337e+18 outside 1..9007199254740991",
    ),
    "bus number 0": (with_entry(TINY_CASE, "bus", 3, 1, "0"), "mpc.bus row 3, column 1 (BUS_I): bus number 0 outside"),
    "wired-in isolated bus": (
        with_entry(_CASE33, "bus", 7, 2, "4"),
        "mpc.bus row 7: bus 7 has type 4 (isolated) but in-service mpc.branch row(s) 6, 7 connect it",
    ),
    "huge bus type": (with_entry(TINY_CASE, "bus", 2, 2, "1e300"), "mpc.bus row 2: unknown bus type 1e+300"),
    "generator QMAX < QMIN": (with_entry(TINY_CASE, "gen", 1, 4, "-20"), "mpc.gen row 1 (bus 1): QMAX -20 < QMIN -10"),
    "generator PMAX < PMIN": (with_entry(TINY_CASE, "gen", 1, 10, "20"), "mpc.gen row 1 (bus 1): PMAX 10 < PMIN 20"),
    "slack voltage -1": (with_entry(TINY_CASE, "gen", 1, 6, "-1"), "slack voltage -1 p.u. (bus 1) outside [0.5, 1.5] p.u."),
    "slack voltage 12.66 (kV for p.u.)": (with_entry(TINY_CASE, "gen", 1, 6, "12.66"), "slack voltage 12.66 p.u."),
    "voltage limits -5 / 50": (
        with_entry(with_entry(TINY_CASE, "bus", 2, 13, "-5"), "bus", 2, 12, "50"),
        "bus 2 has voltage limits Vmin -5, Vmax 50 p.u.; they must satisfy 0 ≤ Vmin ≤ Vmax and 0.5 ≤ Vmax ≤ 2",
    ),
    "zero-impedance branch": (
        with_entry(with_entry(TINY_CASE, "branch", 2, 3, "0"), "branch", 2, 4, "0"),
        "branch 2 (2-3) is in service with zero impedance (r = x = 0)",
    ),
    "branch from a bus to itself": (with_entry(TINY_CASE, "branch", 2, 2, "2"), "branch 2 (2-2) connects a bus to itself"),
    "phase shift 1e308°": (with_entry(TINY_CASE, "branch", 2, 10, "1e308"), "branch 2 (2-3) has phase shift 1e+308°"),
    "tap 1e-300": (with_entry(TINY_CASE, "branch", 2, 9, "1e-300"), "branch 2 (2-3) has an admittance that is not a finite"),
    "branch status 2": (with_entry(TINY_CASE, "branch", 2, 11, "2"), "mpc.branch row 2, column 11 (BR_STATUS): 2; a status is 1"),
    "branch status 0.5": (with_entry(TINY_CASE, "branch", 2, 11, "0.5"), "(BR_STATUS): 0.5; a status is 1 (in service) or 0"),
    "generator status -1": (with_entry(TINY_CASE, "gen", 1, 8, "-1"), "mpc.gen row 1, column 8 (GEN_STATUS): -1"),
    "two slack generators, two voltages": (
        TINY_CASE.replace("mpc.gen = [\n", "mpc.gen = [\n\t1\t0\t0\t10\t-10\t1.05\t100\t1\t10" + "\t0" * 12 + ";\n"),
        "mpc.gen rows 1 and 2 (bus 1) hold different voltages VG 1.05 and 1 p.u.",
    ),
    "voltage limits [0, 0]": (
        with_entry(with_entry(TINY_CASE, "bus", 2, 12, "0"), "bus", 2, 13, "0"),
        "bus 2 has voltage limits Vmin 0, Vmax 0 p.u.; they must satisfy 0 ≤ Vmin ≤ Vmax and 0.5 ≤ Vmax ≤ 2",
    ),
    "negative base kV": (with_entry(TINY_CASE, "bus", 2, 10, "-12.66"), "bus 2 has base voltage -12.66 kV; it must be ≥ 0"),
    "base kV 1e308 in the ohm conversion": (
        with_entry(TINY_CASE, "bus", 1, 10, "1e308"),
        "line 26: the ohm → p.u. conversion over- or underflows (base impedance inf ohm from BASE_KV 1e+308 kV",
    ),
    "base kV 1e200 (its square overflows)": (with_entry(TINY_CASE, "bus", 1, 10, "1e200"), "conversion over- or underflows"),
    "baseMVA 1e-308": (TINY_CASE.replace("mpc.baseMVA = 10;", "mpc.baseMVA = 1e-308;"), "conversion over- or underflows"),
    "baseMVA 1e9 in a p.u. case": (
        TINY_CASE.replace("mpc.baseMVA = 10;", "mpc.baseMVA = 1e9;").split("[PQ, PV")[0],
        "base_mva 1e+09 MVA outside [0.001, 1e+06] MVA",
    ),
    "Python-only number 1_00": (with_entry(TINY_CASE, "bus", 2, 3, "1_00"), "column 3: non-numeric entry '1_00'"),
    "Arabic-Indic digits": (with_entry(TINY_CASE, "bus", 2, 3, "١٠٠"), "column 3: non-numeric entry '١٠٠'"),
    "a transposed matrix": (
        TINY_CASE.replace("];\nmpc.gen", "]';\nmpc.gen", 1),
        'mpc.bus = [...] is followed by "\';"; a matrix',
    ),
    "a matrix times a number": (TINY_CASE.replace("];\nmpc.branch", "] * 1e3;\nmpc.branch", 1), "is followed by '* 1e3;'"),
    "a matrix defined twice": (
        TINY_CASE.replace(
            "mpc.gencost = [", "mpc.bus = [\n\t9\t1\t0\t0\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;\n];\nmpc.gencost = ["
        ),
        "line 16: mpc.bus is defined a second time (first at line 4)",
    ),
}


@pytest.mark.parametrize("label", BAD_VALUES)
@pytest.mark.parametrize("command", [["pf"], ["snapshot", "--strategy", "llma"]])
def test_case_values_outside_their_domain_exit_2_naming_them(capsys, tmp_path, label, command):
    text, message = BAD_VALUES[label]
    path = tmp_path / "case.m"
    path.write_text(text)
    code, err = _cli(capsys, [command[0], str(path), *command[1:]])
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"opfbench {command[0]}: error: {path}") and message in err, err


def test_a_byte_order_mark_and_windows_line_ends_read_as_the_plain_file(tmp_path):
    from opfbench.io.matpower import load_case_file

    plain, marked = tmp_path / "plain.m", tmp_path / "marked.m"
    plain.write_text(TINY_CASE)
    marked.write_bytes(("\ufeff" + TINY_CASE.replace("\n", "\r\n")).encode("utf-8"))
    a, b = load_case_file(plain), load_case_file(marked)
    assert np.array_equal(a.ybus.view(float), b.ybus.view(float)) and np.array_equal(a.load_p_mw, b.load_p_mw)


def test_a_diverging_flow_prints_no_floating_point_warnings(tmp_path):
    path = tmp_path / "huge.m"
    path.write_text(with_entry(TINY_CASE, "bus", 2, 5, "1e300"))  # Gs 1e300 MW
    proc = subprocess.run([sys.executable, "-m", "opfbench", "pf", str(path), "--json"], capture_output=True, text=True)
    assert proc.returncode == 1 and proc.stderr == "" and json.loads(proc.stdout)["losses_kw"] is None


def test_an_isolated_bus_is_refused_not_turned_into_a_load_bus(tmp_path):
    from opfbench.errors import CaseFormatError
    from opfbench.io.matpower import load_case_file

    text = with_entry(with_entry(TINY_CASE, "bus", 3, 2, "4"), "branch", 2, 11, "0")  # bus 3 type 4, its branch out
    path = tmp_path / "isolated.m"
    path.write_text(text)
    with pytest.raises(CaseFormatError, match="mpc.bus row 3: bus 3 has type 4 .isolated.; remove the bus"):
        load_case_file(path)


def test_strategy_options_are_type_checked(net):
    from opfbench.registry.catalog import run_strategy

    scenario = Scenario.snapshot(net)
    for name, options, message in (
        ("acopf", {"slack_export": "false"}, "'acopf': option slack_export: 'false' is not a bool like its default 'true'"),
        ("acopf", {"slack_export": 0}, "'acopf': option slack_export: 0 is not a bool like its default 'true'"),
        ("socp", {"slack_export": None}, "option slack_export: None is not a bool"),
        ("llma", {"safe": "yes"}, "'llma': option safe: 'yes' is not a bool like its default 'false'"),
        ("acopf", {"fallback": 1}, "'acopf': option fallback: 1 is not a choice like its default 'chain'"),
        ("acopf", {"fallback": "maybe"}, "'acopf': option fallback: 'maybe' is not one of chain, paper"),
        ("volt-var", {"v": (1.0, 0.9), "q": (0.1, 0.0)}, "the curve's v values must increase"),
    ):
        with pytest.raises(InputError, match=message):
            run_strategy(name, scenario, 0.0, **options)
    exporting = run_strategy("acopf", scenario, 0.0, slack_export=np.bool_(False))
    assert exporting.extra["slack_export"] is False


@pytest.mark.parametrize("label", BAD_CASES)
def test_malformed_case_file_exit_2_naming_file_and_row(capsys, tmp_path, label):
    text, message = BAD_CASES[label]
    path = tmp_path / "bad.m"
    path.write_text(text)
    code, err = _cli(capsys, ["pf", str(path)])
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"opfbench pf: error: {path}") and message in err


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            TINY_CASE.replace("%% in Volts", "%% in Volts \xe9").encode("latin-1"),
            "not a text MATPOWER file (byte 763 is not UTF-8)",
        ),
        (b"\x00\x01\x02mpc" * 10, "not a text MATPOWER file (contains NUL bytes)"),
        (bytes(range(256)), "is not UTF-8"),
    ],
)
def test_binary_or_non_utf8_case_file_exit_2(capsys, tmp_path, data, message):
    path = tmp_path / "bad.m"
    path.write_bytes(data)
    code, err = _cli(capsys, ["snapshot", str(path), "--strategy", "llma"])
    assert code == 2 and str(path) in err and message in err


def test_out_of_memory_is_one_message_naming_the_case(capsys, monkeypatch):
    def too_big(name):
        raise MemoryError

    monkeypatch.setattr("opfbench.io.load_case", too_big)  # the command imports it when it runs
    code, err = _cli(capsys, ["pf", "case10000"])
    assert code == 2 and err == (
        "opfbench pf: error: out of memory on case 'case10000': the problem is too large "
        "for this machine's memory (a smaller case, or fewer snapshots)\n"
    )


# ----- the shared network is immutable ----------------------------------------------------
def test_cached_network_arrays_are_read_only():
    net = load_network("paper33")
    for name in ("load_p_mw", "load_q_mvar", "r", "x", "vmin", "vmax", "bus_ids", "status", "f"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(net, name)[0] = 0
    assert load_network("paper33").load_p_mw.sum() == pytest.approx(3.715)


def _nominal_losses_kw(net) -> float:
    from opfbench.powerflow import bus_injections, solve_pf

    return float(solve_pf(net, bus_injections(net, 0.8 * net.der_rating_mw, 0.0, 1.0)).losses_kw)


@pytest.mark.filterwarnings("ignore::scipy.sparse.SparseEfficiencyWarning")  # the refused new entry
@pytest.mark.parametrize("case", ["paper33", "case141-der"])  # the dense and the sparse solvers
def test_derived_solver_data_is_read_only_and_never_shared_writable(case):
    net = load_network(case)
    before = _nominal_losses_kw(net)
    y = net.ybus_sparse
    writes = {
        "Y-bus data": lambda: y.data.__setitem__(0, 0),
        "Y-bus indices": lambda: y.indices.__setitem__(0, 1),
        "Y-bus indptr": lambda: y.indptr.__setitem__(1, 0),
        "Y-bus entry": lambda: y.__setitem__((0, 0), 5.0),
        "Y-bus new entry": lambda: y.__setitem__((0, net.n_bus - 1), 100.0),
        "Y-bus scaled in place": lambda: y.__imul__(2.0),
        "dense Y-bus": lambda: net.ybus.__setitem__((0, 0), 0),
        "branch admittance": lambda: net.branch_admittances[0].__setitem__(0, 0),
        "BFS parent": lambda: net.parent.__setitem__(3, 0),
        "BFS order": lambda: net.bfs_order.__setitem__(0, 2),
        "BFS parent branch": lambda: net.parent_branch.__setitem__(3, 0),
    }
    refused = []
    for label, write in writes.items():
        with pytest.raises(ValueError, match="read-only"):
            write()
        refused.append(label)
    assert refused == list(writes)
    assert net.ybus_sparse is not net.ybus_sparse  # each caller gets its own matrix object over the frozen arrays
    assert _nominal_losses_kw(load_network(case)) == before > 0


def test_with_changes_refuses_an_inconsistent_network():
    from opfbench.errors import NetworkError

    net = load_network("paper33")
    n = net.n_bus
    at = np.arange(n)
    bad = {
        "slack moved without its type": ({"slack": 5}, "slack is bus 6 (index 5) but bus_type marks 1 as the slack"),
        "two slack buses": ({"bus_type": np.where(at == 5, 3, net.bus_type)}, "marks 1, 6 as the slack"),
        "no slack type": ({"bus_type": np.ones(n, dtype=int)}, "marks none as the slack"),
        "type 4": ({"bus_type": np.where(at == 5, 4, net.bus_type)}, "bus 6 has type 4; expected 1 (PQ), 2 (PV), 3 (slack)"),
        "slack index as text": ({"slack": "0"}, "slack must be a bus index (an integer), got '0'"),
        "slack voltage -1": ({"v_slack": -1.0}, "slack voltage -1 p.u. (bus 1) outside [0.5, 1.5]"),
        "slack voltage NaN": ({"v_slack": float("nan")}, "v_slack must be finite, got nan"),
        "slack voltage as text": ({"v_slack": "1.0"}, "v_slack must be a real number, got '1.0'"),
        "limits -5 / 50": (
            {"vmin": np.where(at == 4, -5.0, net.vmin), "vmax": np.where(at == 4, 50.0, net.vmax)},
            "bus 5 has voltage limits Vmin -5, Vmax 50 p.u.; they must satisfy 0 ≤ Vmin ≤ Vmax and 0.5 ≤ Vmax ≤ 2",
        ),
        "duplicated bus number": ({"bus_ids": np.where(at == 7, 7, net.bus_ids)}, "bus number 7 is used by more than one bus"),
        "fractional bus number": ({"bus_ids": net.bus_ids + 0.5}, "bus_ids must be whole numbers, got 1.5"),
        "bus numbers as text": ({"bus_ids": net.bus_ids.astype(str)}, "bus_ids must be real numbers, got <U"),
        "zero impedance": (
            {"r": np.where(np.arange(net.n_branch) == 3, 0, net.r), "x": np.where(np.arange(net.n_branch) == 3, 0, net.x)},
            "branch 4 (4-5) is in service with zero impedance (r = x = 0)",
        ),
        "tap 0": ({"tap": np.where(np.arange(net.n_branch) == 3, 0.0, net.tap)}, "branch 4 (4-5) has tap ratio 0"),
        "complex resistance": ({"r": net.r + 1j}, "r must be real numbers, got complex128"),
    }
    for changes, message in bad.values():
        with pytest.raises(NetworkError, match=re.escape(message)):
            net.with_changes(**changes)
    moved = net.with_changes(slack=5, bus_type=np.where(at == 5, 3, np.where(at == 0, 1, net.bus_type)))
    assert moved.slack == 5 and moved.bfs_order[0] == 5  # a consistent move is fine


def test_wrong_types_through_the_python_api_name_what_is_wrong():
    from opfbench.errors import NetworkError
    from opfbench.network import DER
    from opfbench.registry.catalog import run_strategy

    net = load_network("paper33")
    scenario = Scenario.snapshot(net)
    refused = [
        (NetworkError, lambda: net.with_changes(name=None), "a network's name must be text, got None"),
        (NetworkError, lambda: net.with_changes(ders=("PV",)), "ders[0] is 'PV', not a DER unit"),
        (NetworkError, lambda: net.with_changes(ders=(DER(3.5, "PV", 0.5),)), "ders[0] has bus 3.5; a DER's bus is an"),
        (NetworkError, lambda: net.with_changes(ders=(DER(True, "PV", 0.5),)), "ders[0] has bus True"),
        (NetworkError, lambda: net.with_changes(ders=(DER(3, "PV", "0.5"),)), "ders[0] has rating_mw '0.5'; it must be a"),
        (NetworkError, lambda: net.with_changes(colour="red"), "paper33: a network has no field colour"),
        (NetworkError, lambda: net.index_of("5"), "paper33: a bus number is an integer, got '5'"),
        (
            InputError,
            lambda: load_network(None),
            f"a case is {formats()}, got None",  # every format, as every help text names them
        ),
        (InputError, lambda: Scenario("paper33", np.ones(1), np.zeros((1, 5))), "scenario: net must be a Network"),
        (InputError, lambda: Scenario(net, "1", np.zeros((1, 5))), "scenario: load_scale must be numeric, got <U1"),
        (InputError, lambda: Scenario(net, True, np.zeros((1, 5))), "scenario: load_scale must be numeric, got bool"),
        (InputError, lambda: Scenario(net, np.zeros(0), np.zeros((0, 5))), "scenario: no snapshot (load_scale is empty)"),
        (InputError, lambda: Scenario(net, np.ones(1), np.zeros((1, 5)), pv_night_q=np.array(["no"])), "pv_night_q must be"),
        (InputError, lambda: Scenario(net, np.ones(1), np.zeros((1, 5)), pv_night_q=[2]), "pv_night_q must be true/false"),
        (InputError, lambda: run_strategy("llma", scenario, "0"), "reserve coefficient k must be a number in [0, 1], got '0'"),
        (InputError, lambda: run_strategy("llma", scenario, True), "reserve coefficient k must be a number in [0, 1], got True"),
        (InputError, lambda: run_strategy("llma", net, 0.0), "strategy 'llma' runs on a Scenario (e.g. Scenario.snapshot"),
        (InputError, lambda: run_strategy("acopf", None, 0.0), "strategy 'acopf' runs on a Scenario (e.g. Scenario.snapshot"),
    ]
    for error, call, message in refused:
        with pytest.raises(error, match=re.escape(message)):
            call()
    listed = net.with_changes(ders=list(net.ders))
    assert isinstance(listed.ders, tuple)  # a list handed in cannot change the network afterwards
    assert run_strategy("llma", scenario, np.float64(0.2)).losses_kw[0] == run_strategy("llma", scenario, 0.2).losses_kw[0]


def test_network_copies_the_callers_arrays():
    net = load_network("case33bw")
    load = np.array(net.load_p_mw)
    other = net.with_changes(load_p_mw=load)
    load[:] = 0  # the caller's array stays writable and the network does not see the change
    assert other.load_p_mw.sum() == pytest.approx(3.715)


def test_network_refuses_negative_r_and_crossed_limits():
    from opfbench.errors import NetworkError

    net = load_network("case33bw")
    with pytest.raises(NetworkError, match=r"branch 3 \(3-4\) has negative resistance"):
        net.with_changes(r=np.where(np.arange(net.n_branch) == 2, -0.01, net.r))
    with pytest.raises(NetworkError, match="bus 7 has voltage limits Vmin 1.05, Vmax 1 p.u."):
        net.with_changes(vmin=np.where(np.arange(net.n_bus) == 6, 1.05, net.vmin), vmax=np.ones(net.n_bus))
    with pytest.raises(NetworkError, match=r"load_p_mw has shape \(32,\), expected \(33,\)"):
        net.with_changes(load_p_mw=net.load_p_mw[:-1])


# ----- Scenario ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def net():
    return load_network("paper33")


def test_scenario_refuses_transposed_der_array(net):
    p = np.full((5, 3), 0.3)  # (n_der, S): the transposed layout
    with pytest.raises(InputError, match=r"der_p_mw must have shape \(S, n_der\) = \(3, 5\).*got \(5, 3\)"):
        Scenario(net, np.ones(3), p)
    with pytest.raises(InputError, match=r"der_p_forecast_mw must have shape \(S, n_der\) = \(3, 5\)"):
        Scenario(net, np.ones(3), np.full((3, 5), 0.3), p)
    with pytest.raises(InputError, match=r"der_p_mw must have shape"):
        Scenario(net, np.ones(2), np.full(10, 0.3))  # flat (S·n_der,) is not reshaped either
    with pytest.raises(InputError, match=r"load_scale must be a number or a 1-D array"):
        Scenario(net, np.ones((3, 1)), np.full((3, 5), 0.3))


def test_scenario_refuses_complex_and_non_numeric(net):
    with pytest.raises(InputError, match="der_p_mw must be real"):
        Scenario(net, [1.0], np.full(5, 0.3 + 0.1j))
    with pytest.raises(InputError, match="load_scale must be real"):
        Scenario(net, [1.0 + 0j], np.full(5, 0.3))
    with pytest.raises(InputError, match="load_scale must be numeric"):
        Scenario(net, ["high"], np.full(5, 0.3))
    with pytest.raises(InputError, match="der_p_mw is not a regular array"):
        Scenario(net, [1.0, 1.0], [[0.3] * 5, [0.3] * 4])


def test_scenario_loads_must_add_up_to_a_finite_number(capsys, net):
    with pytest.raises(InputError, match=r"total load of snapshot 1 \(load_scale 1e\+308 × the nominal loads\) is not a finite"):
        Scenario(net, [1.0, 1e308], np.zeros((2, 5)))
    huge = np.full((1, net.n_load), 1e307)  # each finite, their sum not
    with pytest.raises(InputError, match="total load of snapshot 0 is not a finite number of MW"):
        Scenario.from_series(net, huge, np.zeros_like(huge), np.zeros((1, 5)))
    with pytest.raises(InputError, match="scenario: net must be a Network .*, got NoneType"):
        Scenario.snapshot(None)
    code, err = _cli(capsys, ["pf", "paper33", "--load-scale", "1e308", "--json"])  # printed an overflow warning
    assert code == 2 and err == (
        "opfbench pf: error: scenario: the total load of snapshot 0 (load_scale 1e+308 × the nominal loads) is not a "
        "finite number of MW\n"
    )


def test_scenario_copies_its_inputs(net):
    load, p = np.ones(2), np.full((2, 5), 0.3)
    scenario = Scenario(net, load, p)
    load[:] = -1.0  # would be refused by validation; must not reach the scenario
    p[:] = 99.0
    assert np.all(scenario.load_scale == 1.0) and np.all(scenario.der_p_mw == 0.3)
    with pytest.raises(ValueError, match="read-only"):
        scenario.der_p_mw[0, 0] = 0.6


def test_scenario_names_the_out_of_range_der(net):
    p = np.full((2, 5), 0.3)
    p[1, 2] = 0.7
    with pytest.raises(InputError, match=r"snapshot 1, DER 2 \(bus 19\): 0.7 MW, rating 0.6 MW"):
        Scenario(net, np.ones(2), p)


def test_scenario_refuses_a_forecast_outside_the_rating(net):
    p = np.full((1, 5), 0.3)
    with pytest.raises(InputError, match=r"der_p_forecast_mw must lie in \[0, rating\] MW; snapshot 0, DER 0 \(bus 10\): 1e\+12"):
        Scenario(net, [1.0], p, np.full((1, 5), 1e12))
    with pytest.raises(InputError, match=r"der_p_forecast_mw must lie in \[0, rating\] MW; snapshot 0, DER 0 \(bus 10\): -0.1"):
        Scenario(net, [1.0], p, np.full((1, 5), -0.1))


def test_from_profiles_checks_profile_shapes(net):
    with pytest.raises(InputError, match=r"pv_pu must have the shape of load_pu \(3,\), got \(2,\)"):
        Scenario.from_profiles(net, np.ones(3), np.zeros(2), np.zeros(3))
    with pytest.raises(InputError, match=r"forecast_wind_pu must have the shape of load_pu"):
        Scenario.from_profiles(net, np.ones(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(4))


# ----- forecast files ------------------------------------------------------------------------
def _forecast_dir(tmp_path, values, timestamps=None, raw: bytes | None = None):
    stamps = timestamps or ["2016-06-01T10:00:00+0000", "2016-06-01T10:01:00+0000", "2016-06-01T10:02:00+0000"]
    (tmp_path / "forecast_pv.json").write_text(json.dumps({"run": {"rating_kw": 10.0}}))
    csv = tmp_path / "forecast_pv.csv"
    if raw is not None:
        csv.write_bytes(raw)
    else:
        pd.DataFrame({"timestamp": stamps, "actual": [1.0, 2.0, 3.0], "lstm": values}).to_csv(csv, index=False)
    return tmp_path


@pytest.mark.parametrize(
    ("values", "timestamps", "message"),
    [
        ([1.0, 1e12, 2.0], None, r"column 'lstm', line 3: '1000000000000.0' is outside the plant's range \[0, 10\] kW"),
        ([1.0, 2.0, -0.5], None, r"column 'lstm', line 4: '-0.5' is outside the plant's range"),
        ([1.0, float("inf"), 2.0], None, r"column 'lstm', line 3: 'inf' is not finite"),
        ([1.0, "abc", 2.0], None, r"column 'lstm', line 3: 'abc' is not a number"),
        ([1.0, "", 2.0], None, r"column 'lstm', line 3: '' is not a number"),
        (
            [1.0, 2.0, 3.0],
            ["2016-06-01T10:00:00+0000", "yesterday", "2016-06-01T10:02:00+0000"],
            r"column 'timestamp', line 3: 'yesterday' is not a timestamp",
        ),
        (
            [1.0, 2.0, 3.0],
            ["2016-06-01T10:00:00+0000", "2016-06-01T09:00:00+0000", "2016-06-01T10:02:00+0000"],
            r"column 'timestamp' is not strictly increasing at row 1",
        ),
    ],
)
def test_bad_forecast_values_are_refused_not_clipped(tmp_path, values, timestamps, message):
    folder = _forecast_dir(tmp_path, values, timestamps)
    with pytest.raises(DataError, match=message) as info:
        load_forecast(folder, "pv", "lstm")
    assert str(folder / "forecast_pv.csv") in str(info.value)


def test_non_utf8_forecast_file(tmp_path):
    folder = _forecast_dir(tmp_path, None, raw=b"timestamp,actual,lstm\n\xff\xfe,1,2\n")
    with pytest.raises(DataError, match=r"forecast_pv.csv: not a UTF-8 text file"):
        load_forecast(folder, "pv", "lstm")


def test_good_forecast_file_reads_exactly(tmp_path):
    series = load_forecast(_forecast_dir(tmp_path, [0.0, 2.5, 10.0]), "pv", "lstm")
    assert series.tolist() == [0.0, 2.5, 10.0] and str(series.index.tz) == "UTC"


# ----- forecast command: checked before the computation --------------------------------------
@pytest.fixture
def no_computation(monkeypatch):
    def fail(name):
        raise AssertionError("the data were loaded before the arguments were checked")

    monkeypatch.setattr("opfbench.forecasting.datasets.forecast_dataset", fail)


@pytest.mark.parametrize(
    ("seed", "message"),
    [
        ("-1", "--seed must lie in [0, 4294967295], got -1"),
        (str(2**64), f"--seed must lie in [0, 4294967295], got {2**64}"),
    ],
)
def test_forecast_seed_out_of_range(capsys, no_computation, seed, message):
    code, err = _cli(capsys, ["forecast", "--dataset", "pv", "--quick", "--seed", seed])
    assert code == 2 and err == f"opfbench forecast: error: {message}\n"


def test_forecast_out_on_a_file_or_unwritable_folder(capsys, no_computation, tmp_path):
    target = tmp_path / "taken"
    target.write_text("")
    code, err = _cli(capsys, ["forecast", "--dataset", "pv", "--quick", "--out", str(target)])
    assert code == 2 and err == f"opfbench forecast: error: --out {target}: exists and is not a folder\n"
    code, err = _cli(capsys, ["forecast", "--dataset", "pv", "--quick", "--out", str(target / "sub")])
    assert code == 2 and err.startswith(f"opfbench forecast: error: --out {target / 'sub'}: cannot write there (")


def test_forecast_unknown_model_before_loading(capsys, no_computation):
    code, err = _cli(capsys, ["forecast", "--dataset", "pv", "--models", "lstm,prophet"])
    assert code == 2 and "unknown model(s) prophet" in err


# ----- the loss table -----------------------------------------------------------------------
def test_table_unknown_case_exit_2(capsys):
    code, err = _cli(capsys, ["table", "nope"])
    assert code == 2 and err.startswith("opfbench table: error: unknown case 'nope'") and err.count("\n") == 1


# ----- lazy imports -----------------------------------------------------------------------------
def test_cli_pf_and_forecast_files_do_not_import_torch_statsmodels_matplotlib():
    code = (
        "import sys, contextlib, io\n"
        "import opfbench.cli as cli\n"
        "heavy = ('torch', 'statsmodels', 'matplotlib')\n"
        "cli.build_parser()  # what `opfbench --help` does: not even pandas, scipy or the solvers\n"
        "after_parser = [m for m in heavy + ('pandas', 'scipy', 'cvxpy', 'casadi') if m in sys.modules]\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    rc = cli.main(['pf', 'paper33', '--json'])\n"
        "after_pf = [m for m in heavy if m in sys.modules]\n"
        "from opfbench.forecasting import load_forecast  # what `run --forecast MODEL` reads\n"
        "print(after_parser, after_pf, [m for m in heavy if m in sys.modules], rc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip() == "[] [] [] 0", proc.stderr


def test_api_numbers_of_the_wrong_kind_or_domain(net):
    from opfbench.capability import check_reserve
    from opfbench.study.periods import resolve_period

    for k in ("0.5", True, None):
        with pytest.raises(InputError, match="reserve coefficient k must be a number in"):
            check_reserve(k)  # type: ignore[arg-type]
    assert check_reserve(np.float32(0.5)) == 0.5 and check_reserve(np.array(0.25)) == 0.25
    for step in (0.0, -5, True, float("nan")):  # 0 read as "not given": the period's own step
        with pytest.raises(InputError, match="--step-minutes must be a finite number of minutes > 0"):
            resolve_period("paper-day", "sun", step)
    with pytest.raises(InputError, match=r"scenario: pv_pu has NaN or inf at index \(1,\)"):
        Scenario.from_profiles(net, np.ones(3), np.array([0.1, np.nan, 0.1]), np.zeros(3))


@pytest.mark.parametrize(
    "command",
    [
        ["run", "--case", "case33bw?der=99:PV:0.5"],  # the case spec is refused while the run plans
        ["run", "--case", "paper33", "--period", "2031-01-01..2031-01-02"],  # a period outside the data
        ["fault", "paper33", "--fault-bus", "17", "--time", "25:00"],
    ],
)
def test_a_refused_command_leaves_no_out_folder_behind(capsys, tmp_path, command):
    out = tmp_path / "made" / "out"
    assert main([*command, "--out", str(out)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "made").exists()  # nor the parent it would have made
