"""A real Dask cluster on localhost — a scheduler and two workers started as separate
processes, as on other machines — runs a small grid through `--scheduler`; the table is
bit-identical (timing columns aside) to the in-process run, and to a local cluster's."""

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.study import StudyConfig, run_study

ROOT = Path(__file__).resolve().parents[1]
CONFIG = StudyConfig(
    strategies=("no-action", "lfma", "acopf", "socp"),
    ks=(0.0, 0.4),
    night_modes=("connected",),
    forecast=("off", "oracle"),
    period="2016-06-28T19:50..2016-06-28T20:10",
    detail=False,
)
TIMING = ["wall_ms", "solver_ms"]
DASK = [sys.executable, "-m", "distributed.cli"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def cluster(tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = os.environ | {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    log = open(tmp_path / "dask.log", "w")
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--no-dashboard",
            ],
            env=env,
            cwd=ROOT,
            stdout=log,
            stderr=log,
        )
    ]
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline and procs[0].poll() is None, (tmp_path / "dask.log").read_text()
                time.sleep(0.2)
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "distributed.cli.dask_worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                    ],
                    env=env,
                    cwd=ROOT,
                    stdout=log,
                    stderr=log,
                )
            )
        from dask.distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
        log.close()


def test_cluster_equals_in_process(cluster, tmp_path):
    local = run_study(CONFIG, tmp_path / "local", quiet=True)
    assert len(local.tasks) == 4
    args = [
        "run",
        "--period",
        CONFIG.period,
        "--strategies",
        *CONFIG.strategies,
        "--k",
        "0",
        "0.4",
        "--night-modes",
        "connected",
        "--no-detail",
        "--quiet",
    ]
    assert main([*args, "--scheduler", cluster, "--out", str(tmp_path / "cluster")]) == 0
    a = pd.read_parquet(local.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(tmp_path / "cluster" / "steps.parquet").drop(columns=TIMING)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert (a.strategy == "acopf").sum() == 2 * 20 and set(a.night) == {False, True}
