"""Ctrl-C (SIGINT) during an in-process run — while IPOPT solves, which swallows the
signal — stops the run promptly with exit code 130, keeps the finished tasks, and the
next run resumes from them; on two workers and during a fault study it is one line too,
never a worker's or numba's traceback."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from opfbench.study import StudyConfig, run_study
from opfbench.study.store import finished_tasks
from tests.support.processes import ROOT, ctrl_c_when

PERIOD = "2016-06-28T10:00..2016-06-28T11:00"
KS = ("0", "0.2", "0.4", "0.6", "0.8")


@pytest.mark.slow  # a fresh process (start-up of several seconds) and two AC OPF runs
def test_ctrl_c_stops_keeps_and_resumes(tmp_path):
    out = tmp_path / "run"
    args = [
        "run",
        "--period",
        PERIOD,
        "--strategies",
        "no-action",
        "acopf",
        "--k",
        *KS,
        "--night-modes",
        "connected",
        "--forecast",
        "off",
        "--workers",
        "1",
        "--no-detail",
        "--out",
        str(out),
    ]
    # Ctrl-C once the first task is saved: the second one is solving
    proc, _, err, after_s = ctrl_c_when([sys.executable, "-m", "opfbench", *args], lambda: finished_tasks(out) > 0)
    assert proc.returncode == 130 and after_s < 30, err
    kept = finished_tasks(out)
    assert 1 <= kept < len(KS) and f"stopped; {kept} tasks kept" in err
    assert not (out / ".lock").exists()
    config = StudyConfig(
        strategies=("no-action", "acopf"),
        ks=tuple(float(k) for k in KS),
        night_modes=("connected",),
        forecast=("off",),
        period=PERIOD,
        detail=False,
    )
    resumed = run_study(config, out)
    assert resumed.ran == len(KS) - kept and len(resumed.summary) == 2 * len(KS)


def _interrupt_when(args: list[str], ready, tmp_path) -> tuple[int, str]:
    """Start `opfbench ARGS` in a process group of its own (as a terminal's foreground job),
    send Ctrl-C (SIGINT) to the whole group once `ready()`, return its exit code and stderr
    after checking that no process of the group is left."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "opfbench", *args],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 240
        while not ready():
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)  # the terminal sends it to every process of the job
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    for _ in range(100):  # the local cluster's workers are gone too
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        raise AssertionError("worker processes outlived the run")
    return proc.returncode, err


@pytest.mark.slow  # a fresh process and a local cluster
def test_ctrl_c_on_two_workers_is_one_line(tmp_path):
    """The local cluster's worker processes never see the terminal's Ctrl-C: no Dask
    worker traceback, exit 130, one line saying what was kept."""
    out = tmp_path / "run"
    args = ["run", "--period", PERIOD, "--strategies", "no-action", "acopf", "--k", *KS, "--night-modes", "connected"]
    code, err = _interrupt_when(
        [*args, "--forecast", "off", "--workers", "2", "--quiet", "--out", str(out)], lambda: finished_tasks(out) > 0, tmp_path
    )
    assert code == 130 and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip() == f"opfbench run: stopped; {finished_tasks(out)} tasks kept in {out}; rerun the same command to resume"
    assert not (out / ".lock").exists()


def test_ctrl_c_during_a_fault_study_is_one_line(tmp_path):
    """Ctrl-C while the fault study simulates (numba code in this process) stops it with
    exit 130 and one line; the finished tasks are kept and the study resumes from them."""
    out = tmp_path / "fault"
    args = ["fault", "paper33", "--fault-bus", "17", "27", "--t-end", "2", "--workers", "1", "--quiet", "--out", str(out)]
    code, err = _interrupt_when(args, lambda: finished_tasks(out) > 0, tmp_path)
    assert code == 130 and "Traceback" not in err, err
    kept = finished_tasks(out)
    assert err.strip() == f"opfbench fault: stopped; {kept} tasks kept in {out}; rerun the same command to resume"
    resumed = subprocess.run([sys.executable, "-m", "opfbench", *args], cwd=ROOT, capture_output=True, text=True)
    assert resumed.returncode == 0 and f"resuming: {kept}/" not in resumed.stderr  # --quiet: no progress
    tasks = json.loads((out / "manifest.json").read_text())["tasks"]
    assert finished_tasks(out) == len(tasks) and all(t["done"] for t in tasks) and (out / "fault.parquet").exists()
