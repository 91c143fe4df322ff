"""A real Dask cluster on localhost — a scheduler and two workers started as separate
processes, as on other machines — runs a small grid through `--scheduler`; the table is
bit-identical (timing columns aside) to the in-process run, and to a local cluster's;
tasks of one affinity run in one worker process, each saved as soon as it finishes."""

import json
import os
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.errors import Stopped
from opfbench.study import StudyConfig, run_study, tasks
from opfbench.study.engine import Reporter
from opfbench.study.execution import run_dask
from opfbench.study.store import finished_tasks

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
        self.id, self.affinity, self.cost = name, affinity, 1.0


def test_tasks_of_one_affinity_run_back_to_back_in_one_worker(dask_cluster):
    """With at least as many affinity groups as the cluster has threads, the tasks of one
    affinity run in one worker process, one after the other, no other group's task in
    between (each result saved)."""
    jobs = [(_Task(f"t{i}", f"a{i % 4}"), i) for i in range(8)]
    saved: list[tuple[int, int]] = []
    run_dask(jobs, lambda i: (time.sleep(0.05), i, os.getpid())[1:], saved.append, 1, dask_cluster)
    pid = dict(saved)
    assert sorted(pid) == list(range(8)) and all(pid[i] == pid[i + 4] for i in range(4))
    for worker in set(pid.values()):  # its tasks in the order they finished: pairs of one group
        groups = [i % 4 for i, p in saved if p == worker]
        assert groups[::2] == groups[1::2], saved


def test_a_groups_first_result_is_saved_before_its_sibling_runs(dask_cluster, tmp_path):
    """Two groups of two on the two-worker cluster: each group's first result reaches
    `save` while its sibling has yet to finish — the sibling waits for a gate that only
    the saving opens (one job per group would wait for it in vain) — and the sibling runs
    in the worker process that ran the first."""

    def after_gate(i: int) -> tuple[int, int, bool]:  # defined here: sent by value, no import in the workers
        gate, deadline = tmp_path / str(i - 2), time.monotonic() + 20
        while i >= 2 and not gate.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        return i, os.getpid(), i < 2 or gate.exists()

    jobs = [(_Task(f"t{i}", f"a{i % 2}"), i) for i in range(4)]
    saved: list[tuple[int, int, bool]] = []

    def save(result: tuple[int, int, bool]) -> None:
        saved.append(result)
        (tmp_path / str(result[0])).touch()

    run_dask(jobs, after_gate, save, 1, dask_cluster)
    assert sorted(i for i, _, _ in saved) == [0, 1, 2, 3] and all(opened for _, _, opened in saved), saved
    pid = {i: p for i, p, _ in saved}
    assert pid[2] == pid[0] and pid[3] == pid[1]


GROUPED = StudyConfig(
    strategies=("no-action", "volt-var"),
    ks=(0.0, 0.4),
    night_modes=("connected",),
    forecast=("off",),
    period="2016-06-28T17:55..2016-06-28T18:05",  # two chunks: two groups of the k's tasks
    detail=False,
    frontier=False,
)


class _StopAfter:
    """A progress sink that stops the run (Ctrl-C) once `n` tasks are saved."""

    def __init__(self, n: int):
        self.n = n

    def update(self, result: object) -> None:
        self.n -= 1
        if self.n == 0:
            raise KeyboardInterrupt

    def close(self) -> None:
        pass


def test_a_stop_between_a_groups_tasks_keeps_the_first_and_the_resume_skips_it(dask_cluster, tmp_path, monkeypatch):
    """A grouped run on the cluster (two chunks × two k: two groups) stopped once each
    group's first task (k = 0) is saved, while its second (k = 0.4) is held in the worker:
    both k = 0 tasks are on disk, and the resume runs the two others only, leaving the kept
    checkpoints as they were."""
    out, release = tmp_path / "run", tmp_path / "release"

    def held_at_k_04(inp: tasks.TaskInput) -> object:  # run_task, a k = 0.4 task after `release`
        deadline = time.monotonic() + 20
        while inp.task.k == 0.4 and not release.exists():
            if time.monotonic() > deadline:
                raise RuntimeError("the second task of a group ran before the first was saved and the run stopped")
            time.sleep(0.01)
        return tasks.run_task(inp)

    monkeypatch.setattr(tasks, "run_task", held_at_k_04)
    with pytest.raises(Stopped):
        run_study(GROUPED, out, scheduler=dask_cluster, reporter=Reporter(progress=lambda total, done: _StopAfter(2)))
    release.touch()  # the held tasks end (their results go nowhere)
    kept = {path.name: path.read_bytes() for path in (out / "tasks").iterdir()}
    assert finished_tasks(out) == 2
    resumed = run_study(GROUPED, out, scheduler=dask_cluster)
    assert (resumed.kept, resumed.ran) == (4, 2) and sorted(t.k for t in resumed.tasks if Path(t.file).name in kept) == [0, 0]
    assert {name: (out / "tasks" / name).read_bytes() for name in kept} == kept


@pytest.mark.slow  # a local cluster of two worker processes
def test_a_local_run_does_not_wait_for_its_workers_to_exit(tmp_path, monkeypatch):
    """A run on a local cluster returns, its manifest final with the worker processes'
    peak memory as they said it, while the cluster is still shutting down (held here): a
    report written next need not wait for it."""
    from dask.distributed import LocalCluster

    release, close = threading.Event(), LocalCluster.close

    def held_close(self, *args, **kwargs):
        release.wait(30)
        return close(self, *args, **kwargs)

    monkeypatch.setattr(LocalCluster, "close", held_close)
    try:
        run = run_study(GROUPED, tmp_path / "run", workers=2)
        timings = json.loads((run.out / "manifest.json").read_text())["timings"]
        assert run.ran == 4 and timings["workers"] == 2 and timings["worker_peak_rss_mb"] > 50
        assert not release.is_set() and any(t.name == "local-cluster-close" and t.is_alive() for t in threading.enumerate())
    finally:
        release.set()


@pytest.mark.slow  # ~5 s quiet
def test_grouped_cluster_run_equals_in_process(dask_cluster, tmp_path):
    """Two chunks × two k on the two-worker cluster: two affinity groups (a chunk's k
    tasks in one worker); the table is bit-identical to the in-process run's."""
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


@pytest.mark.filterwarnings("ignore:Port .* is already in use")  # the in-process cluster's HTTP server moves
def test_a_task_pinned_to_a_worker_that_is_gone_moves_to_another(monkeypatch):
    """A group's next task pinned to a worker no longer in the cluster (it died) would wait
    for ever: the liveness check moves it to a worker that is there, and its group goes on."""
    from dask.distributed import Client, LocalCluster

    from opfbench.study import execution

    monkeypatch.setattr(execution, "LIVENESS_S", 0.05)
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        chains = execution._Chains(client, lambda i: i * 10, [])
        chains._submit([(_Task("t0", "a"), 0), (_Task("t1", "a"), 1)], 0, "tcp://127.0.0.1:9")  # nobody there
        saved: list[int] = []
        deadline = time.monotonic() + 30
        while chains.running() and time.monotonic() < deadline:
            if not chains.collect(saved.append):
                time.sleep(0.01)
    assert saved == [0, 10] and chains.moved == 1
