"""`opfbench fault`: bad input is one message and exit 2; --json records; --out files
per docs/CONTRACTS.md (fault folder)."""

import json

import pandas as pd
import pytest

from opfbench.cli import main
from tests.support.contracts import check_folder, parse
from tests.support.matpower_texts import CASE4_PV

CASE_SHORT = ["paper33", "--t-end", "0.6"]
SHORT = [*CASE_SHORT, "--strategies", "no-action", "llma", "--k", "0", "0.8"]


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["paper33", "--fault-bus", "99"], "no bus 99"),
        (["paper33", "--fault-bus", "x"], "--fault-bus"),
        (["paper33", "--fault-bus", "17", "--fault-impedance", "-0.1"], "--fault-impedance"),
        (["paper33", "--fault-bus", "17", "--duration-ms", "-5"], "--duration-ms"),
        (["paper33", "--fault-bus", "17", "--duration-ms", "1e12"], "--duration-ms"),
        (["paper33", "--fault-bus", "17", "--t-end", "0"], "--t-end"),
        (["paper33", "--fault-bus", "17", "--t-end", "-1"], "--t-end"),
        (["paper33", "--fault-bus", "17", "--step-ms", "10"], "too large for the fastest time constant"),
        (["paper33", "--fault-bus", "17", "--motor-share", "1.5"], "motor share"),
        (["paper33", "--fault-bus", "17", "--motor-share", "-0.1"], "motor share"),
        (["paper33", "--fault-bus", "17", "--variants", "motors=2"], "variant 'motors=2': motor share must lie in [0, 1]"),
        (["paper33", "--fault-bus", "17", "--variants", "source=abc"], "not a number"),
        (["paper33", "--fault-bus", "17", "--variants", "colour=red"], "unknown key"),
        (["paper33", "--fault-bus", "17", "--time", "25:00"], "--time"),
        (["paper33", "--fault-bus", "17", "--variants", "emf=held,emf-pu=1.05"], "emf and emf-pu both set the source EMF"),
        (["paper33", "--fault-bus", "17", "--variants", "emf-pu=1.05,emf=reset"], "emf and emf-pu both set the source EMF"),
        (["paper33", "--fault-bus", "17", "--variants", "motors=0.3,motors=0.5"], "motors is given twice; give each key once"),
        (["paper33", "--fault-bus", "17", "--strategies", "acopf", "--forecast", "oracle"], "nothing to run"),
        (["paper33", "--fault-bus", "17", "--step-ms", "1e-6"], "lengthen the step (--step-ms) or shorten the simulated time"),
        (["paper33", "--fault-bus", "17", "--t-end", "1e9"], "a simulation of 1e+09 s at a 1-ms step is 1e+12 steps"),
    ],
)
def test_bad_input_is_one_message_and_exit_2(argv, needle, capsys):
    assert main(["fault", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1 and "Traceback" not in err


@pytest.fixture
def no_simulation(monkeypatch):
    """`opfbench fault` must refuse before any simulation."""

    def fail(*args, **kwargs):
        raise AssertionError("a simulation ran before the input was refused")

    monkeypatch.setattr("opfbench.dynamics.study.simulate_task", fail)


def test_a_voltage_controlled_bus_is_refused(tmp_path, capsys, no_simulation):
    """The RMS model holds every generator at a fixed current: a PV bus would start off its
    steady state (every bus "not recovered" at 0.79 p.u., even without a fault)."""
    path = tmp_path / "pv4.m"
    path.write_text(CASE4_PV)
    assert main(["fault", f"{path}?der=3:PV:0.1", "--fault-bus", "2", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "opfbench fault: error: pv4: the fault model does not model voltage-controlled (PV) buses (400); "
        "make them PQ buses (type 1) with fixed P and Q"
    )


@pytest.mark.parametrize("out, message", [("file", "exists and is not a folder"), ("/proc/fault", "cannot write there")])
def test_a_bad_out_is_refused_before_the_simulations(tmp_path, capsys, no_simulation, out, message):
    (tmp_path / "file").write_text("x")
    target = tmp_path / out if out == "file" else out
    assert main(["fault", *SHORT, "--fault-bus", "18", "--workers", "1", "--out", str(target)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


def test_a_bus_given_twice_is_simulated_once(capsys):
    assert main(["fault", *CASE_SHORT, "--fault-bus", "18", "18", "--strategies", "no-action", "--k", "0", "--json"]) == 0
    out, err = capsys.readouterr()
    assert len(json.loads(out)) == 1 and "note: duplicated fault buses dropped: 18" in err


def test_json_and_out_files(tmp_path, capsys):
    out = tmp_path / "fault"
    assert main(["fault", *SHORT, "--fault-bus", "18", "--json", "--out", str(out)]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 4  # 2 strategies × 2 k
    keys = {"fault_bus", "strategy", "k", "forecast", "status", "recovery_ms", "vmin", "motors_stalled", "sim_ms"}
    for r in records:
        assert keys <= set(r) and r["fault_bus"] == 18 and len(r["recovery_ms"]) == 33
        assert r["status"] in ("recovered", "not-recovered", "diverged")
        assert r["vmin"]["18"] < 0.2  # a bolted-through-j0.02 fault
    table = pd.read_parquet(out / "fault.parquet")
    assert check_folder(parse(), "fault", out) == []  # files and columns as docs/CONTRACTS.md says
    assert len(table) == 4 * 33 and table["faulted"].sum() == 4 and table["der_bus"].sum() == 4 * 5
    assert set(table["variant"]) == {"reference"} and set(table["emf"]) == {"reset"}
    traces = pd.read_parquet(out / "traces.parquet")
    assert set(traces["bus"]) == {10, 16, 19, 27, 29, 18}
    assert traces.groupby(["strategy", "k", "bus"])["t_s"].diff().dropna().max() <= 0.005 + 1e-9
    assert traces.loc[traces["bus"] == 18, "q_mvar"].isna().all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["model"]["motors"]["share"] == 0.5 and manifest["fault"]["impedance_pu"] == 0.02


def test_variants_are_labelled(capsys):
    assert (
        main(
            [
                "fault",
                *CASE_SHORT,
                "--fault-bus",
                "27",
                "--strategies",
                "no-action",
                "--k",
                "0",
                "--variants",
                "reference",
                "motors=0.3",
                "emf=held",
                "--json",
            ]
        )
        == 0
    )
    records = json.loads(capsys.readouterr().out)
    assert [r["variant"] for r in records] == ["reference", "motors=0.3", "emf=held"]
    # fewer motors: the voltage at the fault bus recovers sooner
    assert records[1]["recovery_ms"]["27"] < records[0]["recovery_ms"]["27"]


def test_bench_reports_null_without_andes(monkeypatch):
    import opfbench.bench.fault as bench_fault
    import opfbench.dynamics.andes_ref as andes_ref

    monkeypatch.setattr(andes_ref, "andes_available", lambda: False)

    class Study:
        timings = {"study_s": 1.0, "simulations": 0}

    monkeypatch.setattr(bench_fault, "run_fault_study", lambda config, case, **kw: Study())
    f = bench_fault.run()
    assert f["andes_sim_ms"] is None and f["ratio_vs_andes"] is None and f["sim_ms"] > 0 and f["steps"] == 3000
