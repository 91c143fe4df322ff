"""The one study engine: a task family's tasks → checkpoint store → in this process or on
Dask → tables, the same for every family (`opfbench run`'s study, `study.run_family`;
`opfbench fault`'s, `dynamics.study`).

A family (`TaskFamily`) says what to run:
- `tasks`: its pieces of work, each a `Task` with a readable `label` and a `definition()`
  (JSON-ready: everything that decides its rows); the task's id is the label's slug plus
  a hash of the definition, so two different tasks never share an id (or a checkpoint),
  an `affinity`: tasks of one affinity run in one process (`execution`), and a `cost`
  (an estimate of its run time: on Dask the costliest groups start first);
- `manifest()`: its part of the folder's manifest — `config`, `config_digest` (what a
  resume must match) and `data_sha256` (a hash of each input's data: an edited case file
  is refused on resume, never mixed) plus its own fields;
- `job(task)`: the task's picklable input, and `runner()` the module-level function that
  turns it into a `TaskOutput` (its tables by name, `tables[0]` the main one) wherever it
  runs;
- `assembler(out)`: the `Assembler` that receives the finished tasks' tables in planned
  order and writes the folder's files (`outputs`) atomically on `commit`.

The engine (`run_family`) checks the scheduler and the folder, plans (the family is built
by a function it calls), locks the folder, keeps every checkpoint that matches its task's
definition (others are recomputed, with a note), runs the rest in process or on Dask
(local workers or `scheduler`), saves each finished task at once, streams the tables as
tasks finish and commits them. It never prints and never ends the process: it tells its
caller what happens through a `Reporter` (notes, progress; the CLI's writes them to stderr)
and stops on Ctrl-C with `Stopped`, the finished tasks on disk — the same call resumes. A
reporter may stop the process at once instead (`Reporter.hard_stop`: the CLI's, exit code
130 while IPOPT, which swallows the signal, is still solving).
"""

from __future__ import annotations

import re
import shutil
import tempfile
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, NoReturn, Protocol

import pandas as pd
import pyarrow as pa

from opfbench.digests import digest
from opfbench.errors import Stopped
from opfbench.study import execution
from opfbench.timing import elapsed_ms, now

if TYPE_CHECKING:
    from opfbench.study.store import RunStore

LABEL_CHARS = 80  # a task's readable label is cut to this many characters in its id


def slug(text: str) -> str:
    """`text` with every run of characters other than letters, digits and '.' as one '-'."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-")


class Task:
    """Base of a family's task records (frozen dataclasses providing `label` and
    `definition()`). `digest` hashes the definition (`opfbench.digests`); `id` is
    `<label slug>-<16 hex digits of the digest>`; `file` its checkpoint."""

    label: str
    cost: float = 1.0  # its run time's estimate, in any unit common to the family's tasks (`execution`)

    def definition(self) -> dict:
        raise NotImplementedError

    @cached_property
    def digest(self) -> str:
        return digest(self.definition())

    @cached_property
    def id(self) -> str:
        return f"{slug(self.label)[:LABEL_CHARS]}-{self.digest[:16]}"

    @property
    def file(self) -> str:
        return f"tasks/{self.id}.parquet"

    @property
    def affinity(self) -> str:
        """Tasks of one affinity run one after another in one process (`execution`: they
        share work through the process's caches, which changes no digit); default: the
        task alone."""
        return self.id

    def as_dict(self) -> dict:
        """The manifest's entry: id, label, file, sha256 and the definition."""
        return {"id": self.id, "label": self.label, "file": self.file, "sha256": self.digest, "definition": self.definition()}


@dataclass
class TaskOutput:
    """A finished task: its tables by name (the family's `tables`) and wall time (s)."""

    task: Any
    tables: dict[str, pd.DataFrame]
    wall_s: float


class Assembler(Protocol):
    """Receives every task's tables in planned order (`add`), writes the folder's files
    atomically (`commit`, returning the family's result) or drops its temporary files
    (`abort`, also after `commit`)."""

    def add(self, task: Any, tables: dict[str, pa.Table]) -> None: ...

    def commit(self) -> Any: ...

    def abort(self) -> None: ...


class TaskFamily(Protocol):
    """What a study runs (see the module docstring). `kind` names the folder's kind
    ("run", "fault"); `tables` a task's tables, the main one first; `outputs` the files
    the assembler writes; `side_entries` what else its runs write into the folder (a run's
    training, before its manifest); `notes` what planning wants the user to know; `label_fields` the
    config fields that change no result (a resume may change them); `columns(table)` a
    task table's columns (a checkpoint with others was written by another version)."""

    @property
    def kind(self) -> str: ...

    @property
    def tables(self) -> tuple[str, ...]: ...

    @property
    def outputs(self) -> tuple[str, ...]: ...

    @property
    def side_entries(self) -> tuple[str, ...]: ...

    @property
    def label_fields(self) -> tuple[str, ...]: ...

    @property
    def notes(self) -> tuple[str, ...]: ...

    @property
    def tasks(self) -> list[Any]: ...

    def columns(self, table: str) -> list[str]: ...

    def manifest(self) -> dict: ...

    def job(self, task: Any) -> Any: ...

    def runner(self) -> Callable[[Any], TaskOutput]: ...

    def assembler(self, out: Path) -> Assembler: ...

    def timings(self, wall_s: float) -> dict: ...


class ProgressSink(Protocol):
    """Progress over a study's tasks, as a `Reporter` shows it."""

    def update(self, result: TaskOutput) -> None: ...

    def close(self) -> None: ...


class _NoProgress:
    def update(self, result: TaskOutput) -> None:
        pass

    def close(self) -> None:
        pass


def _drop(text: str) -> None:
    """A note nobody is shown (it is kept in the run's `notes` all the same)."""


@dataclass(frozen=True)
class Reporter:
    """How a study talks to whoever runs it. `note(text)`: what the user should know
    (planning notes, checkpoints kept or recomputed, workers); `progress(total, done)`: a
    `ProgressSink` for the tasks (None: none); `hard_stop(message)`: on Ctrl-C while
    the work runs in this process, after the cleanup, say `message` and end the process
    at once (None: the running task finishes and the study raises `Stopped`). The default
    shows nothing and stops gracefully: a program or a notebook using the library."""

    note: Callable[[str], None] = _drop
    progress: Callable[[int, int], ProgressSink] | None = None
    hard_stop: Callable[[str], NoReturn] | None = None


SILENT = Reporter()
"""The library's reporter: shows nothing, stops gracefully."""


@dataclass
class EngineRun:
    """A finished run of a family: its folder, tasks, how many were kept from before and
    run now, wall time (s), the assembler's result and each task's wall time."""

    out: Path
    family: Any
    kept: int = 0
    ran: int = 0
    wall_s: float = 0.0
    result: Any = None
    task_wall: dict = field(default_factory=dict)
    workers: int = 1
    notes: list[str] = field(default_factory=list)


class _Assembly:
    """Hands the finished tasks' tables to the assembler in planned order as they arrive."""

    def __init__(self, store: RunStore, family: TaskFamily, done: set[str], assembler: Assembler):
        self.store, self.family, self.done, self.assembler = store, family, done, assembler
        self.added = 0

    def advance(self, just_saved: tuple[str, dict[str, pa.Table]] | None = None) -> None:
        """Add every next task that is done; `just_saved` (id, tables): a task's tables as
        just written, used instead of reading them back when it is the next one."""
        tasks = self.family.tasks
        while self.added < len(tasks) and tasks[self.added].id in self.done:
            task = tasks[self.added]
            ready = just_saved[1] if just_saved is not None and just_saved[0] == task.id else None
            self.assembler.add(task, self.store.read(task, self.family.tables) if ready is None else ready)
            self.added += 1

    def finish(self) -> Any:
        self.advance()
        if self.added < len(self.family.tasks):
            raise RuntimeError(f"task {self.family.tasks[self.added].id} has no checkpoint in {self.store.tasks_dir}")
        return self.assembler.commit()


def run_family(
    prepare: Callable[[], TaskFamily],
    out: Path | None,
    *,
    workers: int | None = 1,
    scheduler: str | None = None,
    fresh: bool = False,
    command: list[str] | None = None,
    notes: bool = True,
    reporter: Reporter = SILENT,
) -> EngineRun:
    """Plan with `prepare()` and run the family into the folder `out` (None: a temporary
    folder, removed afterwards), resuming its finished tasks. `workers`: local worker
    processes (None: one per core), never more than tasks to run (a note says so when
    more were asked); ignored with a `scheduler` address. Notes and progress go to the
    `reporter` (the run's `notes` keep the notes too); `notes=False` keeps the family's
    planning notes unsaid (a nested run's, which its parent says). Ctrl-C: `Stopped`, or
    the reporter's `hard_stop` (module docstring)."""
    from opfbench.study.store import RunStore, finished_tasks

    said: list[str] = []

    def note(text: str) -> None:
        said.append(text)
        reporter.note(text)

    start = now()
    if scheduler is not None:
        execution.scheduler_endpoint(scheduler)
    temporary = out is None
    folder = Path(tempfile.mkdtemp(prefix="opfbench-")) if out is None else Path(out)
    made = _first_missing(folder)  # a refused run leaves no folder it made behind (nor its made parents)
    try:
        store = RunStore(folder, note)
        stopped_planning = "stopped while planning; nothing was run"

        def planning_stopped() -> None:
            _remove(folder, temporary)
            assert reporter.hard_stop is not None
            reporter.hard_stop(f"\n{' '.join((command or ['opfbench'])[:2])}: {stopped_planning}")

        try:
            with execution.stop_on_ctrl_c(planning_stopped) if reporter.hard_stop else nullcontext():
                family = prepare()
        except KeyboardInterrupt:
            raise Stopped(stopped_planning) from None
        for text in family.notes if notes else ():
            note(text)
        run = EngineRun(store.out, family, notes=said)
        if scheduler is not None and not all((store.out / t.file).exists() for t in family.tasks):
            execution.check_scheduler(scheduler)  # before any work: there is some to do
        with store:
            done = store.open(family, command or [], fresh)
            pending = [t for t in family.tasks if t.id not in done]
            run.kept = len(done)
            run.workers = execution.worker_count(workers, len(pending), scheduler, note)
            progress = reporter.progress(len(family.tasks), len(done)) if reporter.progress else _NoProgress()
            assembly = _Assembly(store, family, done, family.assembler(store.out))

            def save(result: TaskOutput) -> None:
                written = store.save(result, family.tables)
                done.add(result.task.id)
                run.kept += 1
                run.ran += 1
                run.task_wall[result.task.id] = result.wall_s
                progress.update(result)
                assembly.advance((result.task.id, written))

            def kept_note() -> str:
                if temporary:
                    return f"{run.ran} of {len(family.tasks)} tasks had finished (no --out: nothing kept)"
                return f"{run.kept} tasks kept in {store.out}; rerun the same command to resume"

            def stop() -> None:  # Ctrl-C in the in-process path, with a hard stop: every finished task is on disk
                progress.close()
                assembly.assembler.abort()
                store.release()
                _remove(folder, temporary)
                assert reporter.hard_stop is not None
                reporter.hard_stop(f"\nopfbench {family.kind}: stopped; {kept_note()}")

            try:
                assembly.advance()  # the tasks kept from before
                try:
                    jobs = [(t, family.job(t)) for t in pending]
                    worker_peak = execution.execute(
                        jobs, family.runner(), save, run.workers, scheduler, stop if reporter.hard_stop else None
                    )
                except KeyboardInterrupt:
                    raise Stopped(kept_note()) from None
                finally:  # also after an interrupt: the manifest marks the finished tasks
                    progress.close()
                    store.finish_manifest(None, run.workers, scheduler, run.task_wall, {})
                run.result = assembly.finish()
            finally:
                assembly.assembler.abort()
            run.wall_s = elapsed_ms(start) / 1e3
            # the local worker processes' peak memory as they said it: their shutting down is not waited for
            peak = {} if worker_peak is None else {"worker_peak_rss_mb": worker_peak}
            store.finish_manifest(run.wall_s, run.workers, scheduler, run.task_wall, family.timings(run.wall_s) | peak)
        return run
    except Exception:
        if made is not None and not finished_tasks(folder):  # refused, or failed before any task finished
            _remove(made, True)
        raise
    finally:
        _remove(folder, temporary)


def _first_missing(folder: Path) -> Path | None:
    """The outermost folder of `folder`'s path that does not exist yet (None: it exists)."""
    if folder.exists():
        return None
    top = folder.absolute()
    while not top.parent.exists():
        top = top.parent
    return top


def _remove(folder: Path, remove: bool) -> None:
    if remove:
        shutil.rmtree(folder, ignore_errors=True)
