"""A run killed (SIGKILL) at random moments and resumed each time ends with the same
table as an uninterrupted run: the same rows, no duplicates, bit-identical values (the
timing columns aside); damaged checkpoints are recomputed, an edited case file refused."""

import shutil

import pandas as pd

from opfbench.cli import main
from opfbench.formulations import solves as relaxation
from opfbench.study import StudyConfig, run_study
from opfbench.study.store import finished_tasks
from tests.support.checkpoints import KINDS, damage
from tests.support.matpower_texts import TINY_CASE
from tests.support.processes import kill_at_random_moments

# 4 k × 2 chunks (one per local day) = 8 tasks (each with 2 night modes) with the AC OPF
CONFIG = StudyConfig(
    strategies=("no-action", "lfma", "acopf"),
    ks=(0.0, 0.25, 0.5, 0.75),
    night_modes=("connected", "disconnected"),
    forecast=("off",),
    period="2016-06-28T23:30..2016-06-29T00:30",
    chunk="day",
    detail=False,
)
TIMING = ["wall_ms", "solver_ms"]
KEYS = ["case", "strategy", "k", "night_mode", "forecast", "time"]


def _child(out):
    relaxation.forget_solves()  # a fresh process would not have the parent's solves
    run_study(CONFIG, out)


def test_sigkill_at_random_moments_then_resume(tmp_path):
    ref = run_study(CONFIG, tmp_path / "ref")
    assert len(ref.tasks) == 8
    reference_s = ref.wall_s
    out = tmp_path / "killed"
    kills, finished = kill_at_random_moments(_child, (out,), reference_s, 11, (0.05, 0.3))
    assert kills >= 2
    kept = finished_tasks(out)
    resumed = run_study(CONFIG, out)
    assert resumed.kept == 8 and (finished or resumed.ran == 8 - kept)
    a = pd.read_parquet(ref.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(out / "steps.parquet").drop(columns=TIMING)
    assert not b.duplicated(KEYS).any() and len(b) == 3 * 4 * 2 * 60
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert not list(out.glob(".*")) and not list((out / "tasks").glob(".*"))  # no lock, no temporary files


def test_damaged_checkpoints_are_recomputed(tmp_path, capsys):
    """Truncated, empty, another task's, partly missing and another version's checkpoints
    are recomputed, each with a note — never accepted, never a traceback — and the tables are the uninterrupted
    run's."""
    ref = run_study(CONFIG, tmp_path / "ref")
    out = tmp_path / "damaged"
    shutil.copytree(ref.out, out)
    files = damage(out, "summary")
    capsys.readouterr()
    again = run_study(CONFIG, out)
    assert capsys.readouterr().err == ""  # the library tells its caller, it prints nothing
    notes = "\n".join(again.notes)
    assert again.ran == 5 and again.kept == 8
    for file, why in zip(files, KINDS, strict=True):
        assert f"note: {file} {why}" in notes, notes
    for name in ("steps.parquet", "summary.csv"):
        read = pd.read_parquet if name.endswith(".parquet") else pd.read_csv
        a, b = (
            read(folder / name).drop(columns=TIMING if name == "steps.parquet" else ["wall_s", "solver_s"])
            for folder in (ref.out, out)
        )
        pd.testing.assert_frame_equal(a, b, check_exact=True)


def test_an_edited_case_file_is_refused_on_resume(tmp_path, capsys):
    """The case's data hash is in the manifest: a case file edited between an interrupted
    run and its resume is refused (one message, exit 2) instead of mixing two networks;
    --fresh starts over on the new data."""
    path = tmp_path / "tiny.m"
    path.write_text(TINY_CASE)
    out = tmp_path / "run"
    spec = f"{path}?der=3:PV:0.05"
    argv = ["run", "--case", spec, "--strategies", "no-action", "--k", "0", "--night-modes", "connected"]
    argv += ["--forecast", "off", "--period", "2016-06-28T10:00..2016-06-28T10:20", "--workers", "1", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    first = pd.read_csv(out / "summary.csv").energy_kwh.iloc[0]
    path.write_text(TINY_CASE.replace("\t3\t1\t90\t40", "\t3\t1\t95\t40"))
    capsys.readouterr()
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"the data of case {spec} changed since this run began (sha256 " in err, err
    assert "use --fresh to discard them" in err and len(err.splitlines()) == 1 and not (out / ".lock").exists()
    assert main([*argv, "--out", str(out), "--fresh"]) == 0
    assert pd.read_csv(out / "summary.csv").energy_kwh.iloc[0] > first  # bus 3 draws more: more losses


def test_a_folder_of_other_files_is_refused_before_any_work(tmp_path, capsys):
    """A run never writes among files that are no run's (and --fresh never removes them);
    the folder of an earlier run, or an empty one, is taken."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "data").mkdir()
    argv = ["run", "--strategies", "no-action", "--k", "0", "--night-modes", "connected", "--forecast", "off"]
    argv += ["--period", "2016-06-28T10:00..2016-06-28T10:20", "--workers", "1", "--quiet"]
    for extra in ([], ["--fresh"]):
        assert main([*argv, *extra, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert f"--out {out} holds files of no opfbench run (data, notes.txt)" in err and len(err.splitlines()) == 1
        assert sorted(p.name for p in out.iterdir()) == ["data", "notes.txt"]  # nothing written, nothing removed
    fault = ["fault", "paper33", "--fault-bus", "18", "--strategies", "no-action", "--k", "0", "--quiet", "--out", str(out)]
    assert main(fault) == 2 and "holds files of no opfbench fault" in capsys.readouterr().err
    (out / "notes.txt").unlink()
    (out / "data").rmdir()
    assert main([*argv, "--out", str(out)]) == 0 and main([*argv, "--out", str(out)]) == 0  # empty, then its own run
