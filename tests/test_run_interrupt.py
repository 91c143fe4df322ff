"""Ctrl-C (SIGINT) during an in-process run — while IPOPT solves, which swallows the
signal — stops the run promptly with exit code 130, keeps the finished tasks, and the
next run resumes from them."""

import signal
import subprocess
import sys
import time

import pytest

from opfbench.study import StudyConfig, run_study
from opfbench.study.store import finished_tasks
from tests.support.processes import ROOT

PERIOD = "2016-06-28T10:00..2016-06-28T11:00"
KS = ("0", "0.2", "0.4", "0.6", "0.8")
# only the `run` subcommand (the full CLI also imports the forecasting models)
CODE = (
    "import argparse, sys; from opfbench.commands import run; p = argparse.ArgumentParser(); "
    "run.register(p.add_subparsers()); a = p.parse_args(sys.argv[1:]); sys.exit(a.func(a))"
)


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
    proc = subprocess.Popen(
        [sys.executable, "-c", CODE, *args],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 240
        while not finished_tasks(out):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)  # the second task is solving
        sent = time.monotonic()
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130 and time.monotonic() - sent < 30
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
    resumed = run_study(config, out, quiet=True)
    assert resumed.ran == len(KS) - kept and len(resumed.summary) == 2 * len(KS)
