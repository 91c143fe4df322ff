"""The fault study on the study engine: killed (SIGKILL) at random moments and run again it
ends with the uninterrupted study's tables; damaged checkpoints are recomputed, an edited
case file is refused; a real Dask cluster (`--scheduler`) gives the same tables."""

import json
import shutil

import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.dynamics.params import FaultParams
from opfbench.dynamics.study import FaultConfig, run_fault_study
from opfbench.io import load_case
from opfbench.study.store import finished_tasks
from tests.support.checkpoints import KINDS, damage
from tests.support.matpower_texts import TINY_CASE
from tests.support.processes import kill_at_random_moments

CASE = load_case("paper33")
# 2 variants × (no action, LLMA and LFMA at three k: 5 distinct setpoints) = 10 tasks of two
# short simulations
CONFIG = FaultConfig.build(
    case="paper33",
    fault_buses=(18, 27),
    strategies=("no-action", "llma", "lfma"),
    ks=(0.0, 0.4, 0.8),
    variants=("reference", "motors=0.3"),
    fault=FaultParams(bus=0, t_end_s=1.0),
)
TIMING = ["sim_ms"]


def _tables(out) -> tuple[pd.DataFrame, pd.DataFrame]:
    return pd.read_parquet(out / "fault.parquet").drop(columns=TIMING), pd.read_parquet(out / "traces.parquet")


def _same(a, b) -> None:
    for x, y in zip(_tables(a), _tables(b), strict=True):
        pd.testing.assert_frame_equal(x, y, check_exact=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    study = run_fault_study(CONFIG, CASE, tmp_path_factory.mktemp("fault") / "ref")
    assert len(study.family.tasks) == 10 and study.timings["simulations"] == 20
    return study


def _child(out):
    run_fault_study(CONFIG, CASE, out)


def test_sigkill_at_random_moments_then_resume(tmp_path, reference):
    out = tmp_path / "killed"
    kills, finished = kill_at_random_moments(_child, (out,), reference.run.wall_s, 7, (0.1, 0.5))
    assert kills >= 2
    kept = finished_tasks(out)
    resumed = run_fault_study(CONFIG, CASE, out)
    assert resumed.run.kept == 10 and (finished or resumed.run.ran == 10 - kept)
    _same(reference.out, out)
    assert not list(out.glob(".*")) and not list((out / "tasks").glob(".*"))  # no lock, no temporary files


def test_damaged_checkpoints_are_recomputed(tmp_path, reference, capsys):
    out = tmp_path / "damaged"
    shutil.copytree(reference.out, out)
    files = damage(out, "traces")
    capsys.readouterr()
    again = run_fault_study(CONFIG, CASE, out)
    assert capsys.readouterr().err == ""  # the library tells its caller, it prints nothing
    notes = "\n".join(again.run.notes)
    assert again.run.ran == 5 and again.run.kept == 10
    for file, why in zip(files, KINDS, strict=True):
        assert f"note: {file} {why}" in notes, notes
    _same(reference.out, out)


def test_an_edited_case_file_is_refused_on_resume(tmp_path, capsys):
    path = tmp_path / "tiny.m"
    path.write_text(TINY_CASE)
    out = tmp_path / "fault"
    argv = ["fault", f"{path}?der=3:PV:0.05", "--fault-bus", "3", "--strategies", "no-action", "llma", "--k", "0"]
    argv += ["--t-end", "0.4", "--workers", "1", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    path.write_text(TINY_CASE.replace("\t3\t1\t90\t40", "\t3\t1\t95\t40"))  # bus 3 draws 95 kW, not 90
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"the data of case {path}?der=3:PV:0.05 changed since this run began" in err and "--fresh" in err, err
    assert len(err.strip().splitlines()) == 1 and not (out / ".lock").exists()
    assert main([*argv, "--fresh"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["data_sha256"][f"case {path}?der=3:PV:0.05"] == load_case(f"{path}?der=3:PV:0.05").data_sha256


def test_on_a_dask_cluster_like_in_process(dask_cluster, tmp_path, reference):
    argv = ["fault", "paper33", "--fault-bus", "18", "27", "--strategies", "no-action", "llma", "lfma", "--k", "0", "0.4", "0.8"]
    argv += ["--variants", "reference", "motors=0.3", "--t-end", "1", "--quiet"]
    assert main([*argv, "--scheduler", dask_cluster, "--out", str(tmp_path / "cluster")]) == 0
    _same(reference.out, tmp_path / "cluster")
    manifest = json.loads((tmp_path / "cluster" / "manifest.json").read_text())
    assert manifest["kind"] == "fault" and manifest["timings"]["scheduler"] == dask_cluster


def test_a_crash_while_writing_over_an_older_study_leaves_no_mixed_set(tmp_path, reference, monkeypatch):
    """The folder's files are one study's: opening it for another removes the older one's
    tables first, and the new ones are committed traces first, the fault table (what marks
    a fault study) after them — a crash in between leaves no fault table, never one
    beside another study's traces."""
    out = tmp_path / "over"
    shutil.copytree(reference.out, out)
    other = FaultConfig.build(case="paper33", fault_buses=(18,), strategies=("no-action",), ks=(0.0,), fault=CONFIG.fault)

    def crash(path, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("opfbench.dynamics.study.write_parquet", crash)
    with pytest.raises(OSError):
        run_fault_study(other, CASE, out, fresh=True)
    assert not (out / "fault.parquet").exists() and not (out / ".lock").exists()
    assert set(pd.read_parquet(out / "traces.parquet")["fault_bus"]) == {18}  # the new study's alone
    monkeypatch.undo()
    again = run_fault_study(other, CASE, out)  # the same command resumes: nothing to simulate
    assert again.run.ran == 0 and set(pd.read_parquet(out / "fault.parquet")["fault_bus"]) == {18}
