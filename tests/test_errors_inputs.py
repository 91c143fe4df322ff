"""Every bad input gets one clear error naming it (exit code 2 on the command line) —
never a traceback, never a silently wrong result. One test per class of input."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from opfbench.cases import load_case
from opfbench.cli import main
from opfbench.errors import DataError, InputError
from opfbench.forecasting.outputs import load_forecast
from opfbench.scenario import Scenario
from tests.support.matpower_texts import TINY_CASE

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

    monkeypatch.setattr("opfbench.cases.load_case", too_big)  # the command imports it when it runs
    code, err = _cli(capsys, ["pf", "case10000"])
    assert code == 2 and err == (
        "opfbench pf: error: out of memory on case 'case10000': the problem is too large "
        "for this machine's memory (a smaller case, or fewer snapshots)\n"
    )


# ----- the shared network is immutable ----------------------------------------------------
def test_cached_network_arrays_are_read_only():
    net = load_case("paper33")
    for name in ("load_p_mw", "load_q_mvar", "r", "x", "vmin", "vmax", "bus_ids", "status", "f"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(net, name)[0] = 0
    assert load_case("paper33").load_p_mw.sum() == pytest.approx(3.715)


def test_network_copies_the_callers_arrays():
    net = load_case("case33bw")
    load = np.array(net.load_p_mw)
    other = net.with_changes(load_p_mw=load)
    load[:] = 0  # the caller's array stays writable and the network does not see the change
    assert other.load_p_mw.sum() == pytest.approx(3.715)


def test_network_refuses_negative_r_and_crossed_limits():
    from opfbench.errors import NetworkError

    net = load_case("case33bw")
    with pytest.raises(NetworkError, match=r"branch 3 \(3-4\) has negative resistance"):
        net.with_changes(r=np.where(np.arange(net.n_branch) == 2, -0.01, net.r))
    with pytest.raises(NetworkError, match="bus 7 has Vmin 1.05 > Vmax 1"):
        net.with_changes(vmin=np.where(np.arange(net.n_bus) == 6, 1.05, net.vmin), vmax=np.ones(net.n_bus))
    with pytest.raises(NetworkError, match=r"load_p_mw has shape \(32,\), expected \(33,\)"):
        net.with_changes(load_p_mw=net.load_p_mw[:-1])


# ----- Scenario ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def net():
    return load_case("paper33")


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
