"""The study engine's folder safety: task ids that cannot collide, the folder's kind and
schema, where and how many workers run (the scheduler checked before any work)."""

import json
import shutil
import time
from dataclasses import replace

import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.study import StudyConfig
from opfbench.study.engine import slug
from opfbench.study.execution import by_affinity, costliest_first, run_in_process
from opfbench.study.run_family import prepare
from tests.support.matpower_texts import TINY_CASE

RUN = ["run", "--period", "2016-06-28T10:00..2016-06-28T10:20", "--strategies", "no-action", "--night-modes", "connected"]
RUN += ["--forecast", "off", "--quiet"]


def _cli(capsys, argv: list[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err.strip()


def test_task_ids_are_injective():
    """k printed alike (%g) and case paths alike once punctuation is squashed are different
    tasks with different ids; the id carries the readable label and the definition's hash."""
    period = "2016-06-28T10:00..2016-06-28T10:20"
    a, b = prepare(StudyConfig(ks=(0.1, 0.1000001), strategies=("no-action",), forecast=("off",), period=period)).tasks
    assert a.label == b.label == "paper33_k0.1_20160628T1000" and (a.k, b.k) == (0.1, 0.1000001)
    assert a.id == f"{slug(a.label)}-{a.digest[:16]}" and a.id != b.id and a.definition()["k"] == 0.1
    assert len({t.id for t in prepare(StudyConfig(ks=(0.1, 0.1000001))).tasks}) == 2 * 4  # k × chunk


@pytest.fixture(scope="module")
def paper_day_tasks() -> list:
    """The paper day's tasks at k 0 and 0.4, in (k, chunk) order."""
    return prepare(StudyConfig(ks=(0.0, 0.4))).tasks


def test_tasks_of_a_case_and_chunk_share_an_affinity(paper_day_tasks):
    """A run's tasks of one case and chunk — one per k — have one affinity, and
    `by_affinity` groups them in the order of their first task: the paper day's 4 chunks
    × 2 k give 4 groups of the two k's tasks of a chunk."""
    tasks = paper_day_tasks
    groups = by_affinity([(task, i) for i, task in enumerate(tasks)])
    assert [[i for _, i in group] for group in groups] == [[0, 4], [1, 5], [2, 6], [3, 7]]
    assert all({task.k for task, _ in g} == {0.0, 0.4} and len({task.start for task, _ in g}) == 1 for g in groups)


def test_a_tasks_cost_is_its_steps_times_its_cases_buses_and_ders(paper_day_tasks, paper33):
    """A run's task costs its steps × (buses + DERs) of its case; no part of its id."""
    task = paper_day_tasks[0]
    steps = len(pd.date_range(task.start, task.end, freq="1min"))
    assert task.cost == steps * (paper33.n_bus + len(paper33.ders)) == 360 * (33 + len(paper33.ders))
    assert replace(task, cost=1.0).id == task.id


def test_groups_start_costliest_first_ties_in_their_order():
    """On Dask the groups go by their tasks' total cost, the costliest first; equal ones
    keep their order."""
    jobs = [(_Task(f"t{i}", f"a{i % 3}", cost), i) for i, cost in enumerate([1.0, 5.0, 2.0, 2.0, 2.0, 1.0])]
    groups = costliest_first(by_affinity(jobs))
    assert [[i for _, i in group] for group in groups] == [[1, 4], [0, 3], [2, 5]]  # totals 7, 3, 3


class _Task:
    def __init__(self, name: str, affinity: str, cost: float = 1.0):
        self.id, self.affinity, self.cost = name, affinity, cost


def test_in_process_runs_tasks_of_one_affinity_back_to_back():
    """In this process the jobs run group by group (the tasks of one affinity back to back,
    sharing the process's caches), each saved as it finishes."""
    jobs = [(_Task(f"t{i}", f"a{i % 2}"), i) for i in range(5)]
    ran: list[int] = []
    saved: list[int] = []
    run_in_process(jobs, lambda i: ran.append(i) or i, saved.append, None)
    assert ran == saved == [0, 2, 4, 1, 3]


def test_k_printed_alike_are_two_configurations(tmp_path, capsys):
    """Alike by %g, or by pandas' fast CSV float parser: four configurations, in the
    summary and in the report built from it."""
    ks = [0.1, 0.1000001, 0.30000000000000004, 0.3]
    assert main([*RUN, "--k", *map(repr, ks), "--workers", "1", "--out", str(tmp_path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["k"] for r in rows] == ks and len({r["energy_kwh"] for r in rows}) == 1  # no action: k acts on nothing
    assert list(pd.read_csv(tmp_path / "summary.csv", float_precision="round_trip").k) == ks  # written exactly
    assert len(pd.read_parquet(tmp_path / "steps.parquet")) == 4 * 20


def test_case_paths_alike_once_squashed_are_two_cases(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "ok5.m").write_text(TINY_CASE)
    (tmp_path / "t-ok5.m").write_text(TINY_CASE.replace("\t3\t1\t90\t40", "\t3\t1\t190\t40"))  # another load
    energies = {}
    for case in ("t/ok5.m", "t-ok5.m"):
        assert main([*RUN, "--k", "0", "--case", case, "--workers", "1", "--out", f"alone-{case[-6]}", "--json"]) == 0
        energies[case] = json.loads(capsys.readouterr().out)[0]["energy_kwh"]
    assert main([*RUN, "--k", "0", "--case", "t/ok5.m", "t-ok5.m", "--workers", "1", "--out", "both", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["case"]: r["energy_kwh"] for r in rows} == energies and len(set(energies.values())) == 2


def test_a_folder_of_another_kind_or_schema_is_refused(tmp_path, capsys):
    run = tmp_path / "run"
    assert main([*RUN, "--k", "0", "--workers", "1", "--out", str(run)]) == 0
    code, err = _cli(capsys, ["fault", "paper33", "--fault-bus", "18", "--k", "0", "--workers", "1", "--out", str(run)])
    assert (
        code == 2
        and err == f"opfbench fault: error: {run} holds a run folder; give the fault study a folder of its own (another --out)"
    )
    code, err = _cli(capsys, ["fault", "paper33", "--fault-bus", "18", "--k", "0", "--out", str(run), "--fresh"])
    assert code == 2 and "holds a run folder" in err and (run / "steps.parquet").exists()  # --fresh deletes no run
    manifest = json.loads((run / "manifest.json").read_text())
    (run / "manifest.json").write_text(json.dumps(manifest | {"schema": 1}))
    code, err = _cli(capsys, [*RUN, "--k", "0", "--workers", "1", "--out", str(run)])
    assert code == 2 and "written by another opfbench version (manifest schema 1, this one writes 2)" in err, err


@pytest.mark.parametrize(
    "scheduler, message",
    [
        ("not-a-url", "--scheduler 'not-a-url' is not a Dask scheduler address; give tcp://HOST:PORT"),
        ("http://127.0.0.1:8786", "is not a Dask scheduler address"),
        ("tcp://127.0.0.1:99999", "is not a Dask scheduler address"),
        ("tcp://127.0.0.1:1", "--scheduler tcp://127.0.0.1:1: no Dask scheduler answers there (Connection refused)"),
    ],
)
@pytest.mark.parametrize("command", ["run", "fault"])
def test_a_bad_scheduler_is_one_message_at_once(tmp_path, capsys, monkeypatch, scheduler, message, command):
    def fail(*args, **kwargs):
        raise AssertionError("a task ran before the scheduler was refused")

    monkeypatch.setattr("opfbench.study.execution.execute", fail)
    argv = [*RUN, "--k", "0"] if command == "run" else ["fault", "paper33", "--fault-bus", "18", "--k", "0"]
    start = time.monotonic()
    code, err = _cli(capsys, [*argv, "--scheduler", scheduler, "--out", str(tmp_path / "out")])
    assert code == 2 and message in err and len(err.splitlines()) == 1, err
    assert time.monotonic() - start < 10


@pytest.mark.parametrize("command", ["run", "fault"])
def test_workers_are_capped(tmp_path, capsys, monkeypatch, command):
    fault = ["fault", "paper33", "--fault-bus", "18", "--strategies", "no-action", "--k", "0", "--t-end", "0.4"]
    argv = [*RUN, "--k", "0"] if command == "run" else fault
    code, err = _cli(capsys, [*argv, "--workers", "2", "--scheduler", "tcp://127.0.0.1:8786", "--out", str(tmp_path)])
    assert code == 2 and "argument --scheduler: not allowed with argument --workers" in err
    monkeypatch.setattr("opfbench.study.execution.cores", lambda: 2)
    code, err = _cli(capsys, [*argv, "--workers", "12", "--out", str(tmp_path)])
    assert code == 2 and "12 worker processes on 2 cores; give at most 2 (or --scheduler for a Dask cluster)" in err
    monkeypatch.setattr("opfbench.study.execution.run_dask", lambda *a: pytest.fail("a cluster for one task"))
    code, err = _cli(capsys, [*argv, "--workers", "2", "--out", str(tmp_path / "one")])
    assert code == 0 and "note: 1 task(s) to run: 1 worker(s), not 2" in err, err


def test_a_folder_damaged_in_other_ways(tmp_path, capsys):
    """A manifest that is not one is refused (--fresh starts over); a file where tasks/
    belongs is refused; a folder where a checkpoint belongs is recomputed, with a note."""
    out = tmp_path / "run"
    argv = [*RUN, "--k", "0", "--workers", "1", "--out", str(out)]
    assert main(argv) == 0
    (out / "manifest.json").write_text("[1, 2")
    code, err = _cli(capsys, argv)
    assert code == 2 and err.endswith(
        "manifest.json is not a manifest opfbench wrote; use --fresh to start over, or another --out"
    )
    assert main([*argv, "--fresh"]) == 0
    capsys.readouterr()
    task = json.loads((out / "manifest.json").read_text())["tasks"][0]["file"]
    (out / task).unlink()
    (out / task).mkdir()
    code, err = _cli(capsys, argv)
    assert code == 0 and f"note: {task} is partly unreadable" in err, err
    shutil.rmtree(out / "tasks")
    (out / "tasks").write_text("")
    code, err = _cli(capsys, argv)
    assert code == 2 and "tasks is not a folder" in err, err
