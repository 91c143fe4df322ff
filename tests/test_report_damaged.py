"""`opfbench report` on damaged or mismatched inputs: one message naming the file and what
is wrong, exit code 2, no page written — never a traceback, never a page built from an
edited manifest; a folder given for one input must hold that input (as `opfbench run`
checks before its work)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from opfbench.cli import main
from tests.support.report_folders import write_fault, write_run


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    return write_run(tmp_path_factory.mktemp("pristine") / "run")


@pytest.fixture
def run_dir(tmp_path, pristine) -> Path:
    """A copy of a contract-conforming run folder, for one test to damage."""
    return Path(shutil.copytree(pristine, tmp_path / "run"))


def _manifest(run: Path, edit) -> None:
    path = run / "manifest.json"
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def _steps(run: Path, edit) -> None:
    edit(pd.read_parquet(run / "steps.parquet")).to_parquet(run / "steps.parquet", index=False)


def _summary(run: Path, edit) -> None:
    edit(pd.read_csv(run / "summary.csv")).to_csv(run / "summary.csv", index=False)


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


DAMAGE = {
    "truncated steps.parquet": (
        lambda run: _truncate(run / "steps.parquet"),
        "steps.parquet: not a readable parquet file (Parquet magic bytes not found in footer",
    ),
    "empty steps.parquet": (
        lambda run: (run / "steps.parquet").write_bytes(b""),
        "steps.parquet: not a readable parquet file (Parquet file size is 0 bytes)",
    ),
    "steps.parquet that is a CSV": (
        lambda run: (run / "steps.parquet").write_text("case,strategy\npaper33,llma\n"),
        "steps.parquet: not a readable parquet file",
    ),
    "truncated der_q.parquet": (lambda run: _truncate(run / "der_q.parquet"), "der_q.parquet: not a readable parquet file"),
    "binary summary.csv": (
        lambda run: (run / "summary.csv").write_bytes(bytes(range(256)) * 4),
        "summary.csv: not a UTF-8 text file (byte 128)",
    ),
    "empty summary.csv": (
        lambda run: (run / "summary.csv").write_bytes(b""),
        "summary.csv: not a readable CSV table (No columns to parse from file)",
    ),
    "summary.csv of another table": (
        lambda run: (run / "summary.csv").write_text("a,b\n1,2\n"),
        "summary.csv: no column case, strategy, k, night_mode, forecast, steps",
    ),
    "summary.csv with text for a number": (
        lambda run: (run / "summary.csv").write_text(
            (run / "summary.csv")
            .read_text()
            .replace("\npaper33,no-action,0.0,connected,off,144,", "\npaper33,no-action,0.0,connected,off,many,", 1)
        ),
        "summary.csv: column 'steps' holds 'many', not a number",
    ),
    "manifest.json not JSON": (
        lambda run: (run / "manifest.json").write_text('{"config": ['),
        "manifest.json: not valid JSON (Expecting value: line 1 column 13 (char 12))",
    ),
    "manifest.json a list": (
        lambda run: (run / "manifest.json").write_text("[1, 2, 3]"),
        "manifest.json: holds a JSON list, not an object",
    ),
    "manifest.json not UTF-8": (
        lambda run: (run / "manifest.json").write_bytes(b'{"schema": 1, "x": "\xff"}'),
        "manifest.json: not a UTF-8 text file (byte 20)",
    ),
    "price as text": (
        lambda run: _manifest(run, lambda m: m["config"].update(price_per_kwh="cheap")),
        "manifest.json: config.price_per_kwh is 'cheap', expected a finite number ≥ 0",
    ),
    "negative price": (
        lambda run: _manifest(run, lambda m: m["config"].update(price_per_kwh=-1)),
        "manifest.json: config.price_per_kwh is -1, expected a finite number ≥ 0",
    ),
    "config a list": (
        lambda run: _manifest(run, lambda m: m.update(config=[1])),
        "manifest.json: config is [1], expected an object",
    ),
    "cases as text": (
        lambda run: _manifest(run, lambda m: m["config"].update(cases="paper33")),
        "manifest.json: config.cases is 'paper33', expected a list",
    ),
    "unknown schema version": (
        lambda run: _manifest(run, lambda m: m.update(schema=99)),
        "manifest.json: schema 99 is not one this opfbench reads (1..2; a newer one wrote it?)",
    ),
    "no schema": (
        lambda run: _manifest(run, lambda m: m.pop("schema")),
        "manifest.json: schema None is not one this opfbench reads",
    ),
    "schema true": (lambda run: _manifest(run, lambda m: m.update(schema=True)), "manifest.json: schema True is not one"),
    "ks as text": (
        lambda run: _manifest(run, lambda m: m["config"].update(ks=["a"])),
        "manifest.json: config.ks is ['a'], expected a list of numbers in [0, 1]",
    ),
    "ks Infinity": (
        lambda run: (run / "manifest.json").write_text(
            re.sub(r'"ks": \[[^]]*\]', '"ks": [0.0, Infinity]', (run / "manifest.json").read_text())
        ),
        "manifest.json: config.ks is [0.0, inf], expected a list of numbers in [0, 1]",
    ),
    "k 1.5": (
        lambda run: _manifest(run, lambda m: m["config"].update(ks=[0.0, 1.5])),
        "config.ks is [0.0, 1.5], expected a list of numbers in [0, 1]",
    ),
    "currency empty": (
        lambda run: _manifest(run, lambda m: m["config"].update(currency=" ")),
        "manifest.json: config.currency is ' ', expected a printable label",
    ),
    "a name twice in one object": (
        lambda run: (run / "manifest.json").write_text((run / "manifest.json").read_text().replace("{", '{"schema": 9, ', 1)),
        "manifest.json: not valid JSON (the name 'schema' appears twice in one object)",
    ),
    "no config": (lambda run: _manifest(run, lambda m: m.pop("config")), "manifest.json: no config: not the manifest of a run"),
    "a fault study's manifest": (
        lambda run: _manifest(run, lambda m: m["config"].pop("period")),
        "manifest.json: no config.period: not the manifest of a run",
    ),
    "manifest.json a folder": (
        lambda run: ((run / "manifest.json").unlink(), (run / "manifest.json").mkdir()),
        "manifest.json: is not a file (a folder?)",
    ),
    "steps.parquet a folder": (
        lambda run: ((run / "steps.parquet").unlink(), (run / "steps.parquet").mkdir()),
        "steps.parquet: is not a file (a folder?)",
    ),
    "steps k 7": (lambda run: _steps(run, lambda t: t.assign(k=7.0)), "steps.parquet: column 'k' holds 7 outside [0, 1]"),
    "steps losses inf": (
        lambda run: _steps(run, lambda t: t.assign(losses_kw=float("inf"))),
        "steps.parquet: column 'losses_kw' holds inf (",
    ),
    "steps without a status": (
        lambda run: _steps(run, lambda t: t.assign(status=t.status.where(t.index % 5 != 0, None))),
        "row(s) have no status",
    ),
    "steps time without a zone": (
        lambda run: _steps(run, lambda t: t.assign(time=t.time.dt.tz_localize(None))),
        "steps.parquet: column 'time' is time without a time zone, expected time",
    ),
    "der_q q_mvar -inf": (
        lambda run: (pd.read_parquet(run / "der_q.parquet").assign(q_mvar=-float("inf"))).to_parquet(run / "der_q.parquet"),
        "der_q.parquet: column 'q_mvar' holds -inf",
    ),
    "a case entry as text": (
        lambda run: _manifest(run, lambda m: m.update(cases={"paper33": "big"})),
        "manifest.json: cases.paper33 is 'big', expected an object",
    ),
    "DER list as text": (
        lambda run: _manifest(run, lambda m: m["cases"]["paper33"].update(ders="many")),
        "manifest.json: cases.paper33.ders is 'many', expected a list",
    ),
    "manifest nested too deeply": (
        lambda run: (run / "manifest.json").write_text("[" * 100_000 + "]" * 100_000),
        "manifest.json: not a run's JSON (nested too deeply to read)",
    ),
    "price NaN literal": (
        lambda run: (run / "manifest.json").write_text(
            (run / "manifest.json").read_text().replace('"price_per_kwh": 0.25', '"price_per_kwh": NaN')
        ),
        "manifest.json: config.price_per_kwh is nan, expected a finite number ≥ 0",
    ),
    "steps without a strategy": (
        lambda run: _steps(run, lambda t: t.assign(strategy=t.strategy.where(t.index % 7 != 0, None))),
        "row(s) have no strategy",
    ),
    "steps k as text": (lambda run: _steps(run, lambda t: t.assign(k=t.k.astype(str))), "steps.parquet: column 'k' is text"),
    "steps time as numbers": (
        lambda run: _steps(run, lambda t: t.assign(time=t.time.astype("int64"))),
        "steps.parquet: column 'time' is number, expected time",
    ),
    "summary rows repeated": (
        lambda run: _summary(run, lambda t: pd.concat([t, t])),
        "summary.csv: configuration case=paper33, strategy=no-action, k=0.0, night_mode=connected, forecast=off has more",
    ),
    "summary without a case": (lambda run: _summary(run, lambda t: t.assign(case=None)), "row(s) have no case"),
    "summary infinite energy": (
        lambda run: _summary(run, lambda t: t.assign(energy_kwh=float("inf"))),
        "summary.csv: column 'energy_kwh' holds inf (",
    ),
    "summary negative count": (
        lambda run: _summary(run, lambda t: t.assign(steps=-5)),
        "summary.csv: column 'steps' holds -5, not a count of steps",
    ),
}


@pytest.mark.parametrize("label", DAMAGE)
def test_damaged_run_folder_exit_2_naming_the_file(capsys, run_dir, label):
    damage, message = DAMAGE[label]
    damage(run_dir)
    code = main(["report", str(run_dir)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"opfbench report: error: {run_dir}/") and message in err, err
    assert f"rebuild it with `opfbench run --out {run_dir}`" in err
    assert not (run_dir / "report.html").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("nope", "forecast_pv.json: not valid JSON"),
        ('{"metrics": {"arima": 5}}', "forecast_pv.json: metrics['arima'] is 5, expected an object of numbers"),
        ('{"metrics": {"arima": {"mse_scaled": "low"}}}', "metrics['arima']['mse_scaled'] is 'low', expected a finite number"),
        ('{"metrics": [1]}', "forecast_pv.json: metrics is [1], expected an object of models"),
        ("[]", "forecast_pv.json: holds a JSON list, not an object"),
        ('{"metrics": {"lstm": {"mape_pct": Infinity}}}', "metrics['lstm']['mape_pct'] is inf, expected a finite number"),
    ],
)
def test_bad_forecast_json_exit_2(capsys, tmp_path, run_dir, text, message):
    folder = tmp_path / "forecast"
    folder.mkdir()
    (folder / "forecast_pv.json").write_text(text)
    code = main(["report", str(run_dir), "--forecast-dir", str(folder)])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err, err


def test_damaged_fault_study_exit_2(capsys, tmp_path, run_dir):
    fault = write_fault(tmp_path / "fault")
    _truncate(fault / "traces.parquet")
    code = main(["report", str(run_dir), "--fault-dir", str(fault)])
    err = capsys.readouterr().err
    assert code == 2 and "traces.parquet: not a readable parquet file" in err, err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("--fault-dir", "holds no fault study (fault.parquet); write one with `opfbench fault CASE --out"),
        ("--forecast-dir", "holds no forecast run (forecast_pv.json or forecast_wind.json)"),
        ("--year-dir", "holds no finished year run (manifest.json with period 'year' and summary.csv)"),
    ],
)
def test_a_folder_given_for_another_input_is_refused(capsys, run_dir, option, message):
    code = main(["report", str(run_dir), option, str(run_dir)])  # the run folder itself
    err = capsys.readouterr().err
    assert code == 2 and f"{option} {run_dir} {message}" in err, err


@pytest.mark.parametrize("folder", ["empty", "fault"])
def test_a_folder_without_a_run_is_refused(capsys, tmp_path, folder):
    target = write_fault(tmp_path / "fault") if folder == "fault" else tmp_path / "empty"
    target.mkdir(exist_ok=True)
    code = main(["report", str(target), "--out", str(tmp_path / "r.html")])
    err = capsys.readouterr().err
    message = "holds no run (no manifest.json)" if folder == "empty" else "manifest.json: no config: not the manifest of a run"
    assert code == 2 and message in err and not (tmp_path / "r.html").exists(), err


def test_report_out_must_be_a_file(capsys, tmp_path, run_dir):
    code = main(["report", str(run_dir), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and f"--out {tmp_path} is a folder; give the report's file name" in err, err
    code = main(["report", str(run_dir), "--out", f"{tmp_path}/new/"])  # not yet a folder: pathlib drops the slash
    err = capsys.readouterr().err
    assert code == 2 and f"argument --out: '{tmp_path}/new/' names a folder" in err and not (tmp_path / "new").exists()
    blocker = tmp_path / "file"
    blocker.write_text("")
    code = main(["report", str(run_dir), "--out", str(blocker / "report.html")])
    err = capsys.readouterr().err
    assert code == 2 and "cannot create the folder" in err, err
    assert main(["report", str(run_dir), "--out", str(tmp_path / "new" / "page.html")]) == 0
    assert (tmp_path / "new" / "page.html").stat().st_size > 0


def test_files_without_rows_are_missing_inputs_not_errors(capsys, run_dir):
    _steps(run_dir, lambda t: t.iloc[:0])
    _summary(run_dir, lambda t: t.iloc[:0])
    assert main(["report", str(run_dir)]) == 0, capsys.readouterr().err
    html = (run_dir / "report.html").read_text()
    assert html.count(f"opfbench run --out {run_dir}") >= 2  # the sections say which command writes them


def test_report_out_in_a_folder_nothing_can_be_written_to(capsys, run_dir):
    code = main(["report", str(run_dir), "--out", "/proc/opfbench-report.html"])  # root passes os.access here
    err = capsys.readouterr().err
    assert code == 2 and "--out /proc/opfbench-report.html: cannot write in /proc" in err, err


def test_run_refuses_a_damaged_report_input_before_its_work(capsys, tmp_path, monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("a task ran before the input was refused")

    monkeypatch.setattr("opfbench.study.tasks.run_task", fail)
    fault = write_fault(tmp_path / "fault")
    _truncate(fault / "fault.parquet")
    argv = ["run", "--period", "2016-06-28T10:00..2016-06-28T10:10", "--strategies", "no-action", "--workers", "1"]
    code = main([*argv, "--fault-dir", str(fault), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2 and "fault.parquet: not a readable parquet file" in err, err
    assert not (tmp_path / "run").exists()
