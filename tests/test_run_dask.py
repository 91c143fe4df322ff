"""A real Dask cluster on localhost — a scheduler and two workers started as separate
processes, as on other machines — runs a small grid through `--scheduler`; the table is
bit-identical (timing columns aside) to the in-process run, and to a local cluster's;
tasks of one affinity run in one worker process."""

import os
import time

import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.study import StudyConfig, run_study
from opfbench.study.execution import run_dask

CONFIG = StudyConfig(
    strategies=("no-action", "lfma", "acopf", "socp"),
    ks=(0.0, 0.4),
    night_modes=("connected",),
    forecast=("off", "oracle"),
    period="2016-06-28T19:50..2016-06-28T20:10",
    detail=False,
)
TIMING = ["wall_ms", "solver_ms"]


def test_cluster_equals_in_process(dask_cluster, tmp_path):
    local = run_study(CONFIG, tmp_path / "local")
    assert len(local.tasks) == 2  # one per k: each runs both forecast sources
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
    assert main([*args, "--scheduler", dask_cluster, "--out", str(tmp_path / "cluster")]) == 0
    a = pd.read_parquet(local.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(tmp_path / "cluster" / "steps.parquet").drop(columns=TIMING)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert (a.strategy == "acopf").sum() == 2 * 20 and set(a.night) == {False, True}


class _Task:
    def __init__(self, name: str, affinity: str):
        self.id, self.affinity = name, affinity


def test_tasks_of_one_affinity_run_in_one_worker(dask_cluster):
    """With at least as many affinity groups as the cluster has threads, the tasks of one
    affinity run as one job, back to back in one worker process (each result saved)."""
    jobs = [(_Task(f"t{i}", f"a{i % 4}"), i) for i in range(8)]
    saved: list[tuple[int, int]] = []
    run_dask(jobs, lambda i: (time.sleep(0.05), i, os.getpid())[1:], saved.append, 1, dask_cluster)
    pid = dict(saved)
    assert sorted(pid) == list(range(8)) and all(pid[i] == pid[i + 4] for i in range(4))


@pytest.mark.slow  # ~5 s quiet
def test_grouped_cluster_run_equals_in_process(dask_cluster, tmp_path):
    """Two chunks × two k on the two-worker cluster: two affinity groups (a chunk's k
    tasks, one job each); the table is bit-identical to the in-process run's."""
    config = StudyConfig(
        strategies=("no-action", "volt-var", "acopf", "socp"),
        ks=(0.0, 0.4),
        night_modes=("connected",),
        forecast=("off",),
        period="2016-06-28T17:55..2016-06-28T18:05",
        detail=False,
    )
    local = run_study(config, tmp_path / "local")
    assert len(local.tasks) == 4 and len({task.affinity for task in local.tasks}) == 2
    args = ["run", "--period", config.period, "--strategies", *config.strategies, "--k", "0", "0.4"]
    args += ["--night-modes", "connected", "--forecast", "off", "--no-detail", "--quiet"]
    assert main([*args, "--scheduler", dask_cluster, "--out", str(tmp_path / "cluster")]) == 0
    a = pd.read_parquet(local.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(tmp_path / "cluster" / "steps.parquet").drop(columns=TIMING)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
