"""The run folder: lock, manifest, one checkpoint file per finished task, and the tables
assembled from them (layout: the run-folder contract).

- Lock: `.lock` holds the PID of the run using the folder; a second run is refused while
  that process lives; a lock left by a dead process is taken over, with a note.
- Manifest: the config and its digest. The same config resumes (finished tasks are
  skipped); another config is refused unless `fresh` (which deletes the previous run's
  files, and only those).
- Checkpoints: `tasks/<id>.parquet` written atomically (temporary file + os.replace);
  its partial sums (`tasks/<id>.summary.parquet`) and detail tables (`.der_q.parquet`,
  `.bus_v.parquet`) beside it are written first, so a task counts as finished only once
  its main file exists.
- Assembly: `steps.parquet` (and the detail tables) streamed task by task in the planned
  order as arrow tables while the run goes on, `summary.csv` from the per-task partial
  sums; all written atomically.
"""

from __future__ import annotations

import io
import os
import platform
import socket
import subprocess
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from opfbench.errors import InputError
from opfbench.folders import check_out_dir
from opfbench.jsonio import write_atomic, write_json
from opfbench.study.config import DETAIL_TABLES, LABEL_FIELDS, StudyConfig
from opfbench.study.periods import Period
from opfbench.study.tables import KEYS, summarize
from opfbench.study.tasks import Task, TaskOutput

SCHEMA = 1
RUN_FILES = ("steps.parquet", "summary.csv", "der_q.parquet", "bus_v.parquet", "report.html", "manifest.json")
SIDE_FILES = ("summary", *DETAIL_TABLES)  # tasks/<id>.<side>.parquet beside tasks/<id>.parquet


def finished_tasks(out: Path) -> int:
    """How many finished tasks the run folder `out` holds (their main files)."""
    side = tuple(f".{name}.parquet" for name in SIDE_FILES)
    return sum(not f.name.endswith(side) for f in (out / "tasks").glob("*.parquet"))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _versions() -> dict:
    import importlib.metadata as md
    import sys

    out: dict[str, str | None] = {"python": sys.version.split()[0]}
    for name in ("numpy", "scipy", "pandas", "casadi", "cvxpy", "clarabel", "dask"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = None
    return out


def _git_commit() -> str | None:
    try:
        res = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() or None if res.returncode == 0 else None


def _case_info(case: str) -> dict:
    from opfbench.io import load_case

    loaded = load_case(case)
    net = loaded.network
    return {
        "buses": int(net.n_bus),
        "ders": [{"bus": int(net.bus_ids[d.bus]), "kind": d.kind, "rating_mw": float(d.rating_mw)} for d in net.ders],
        "vmin_pu": float(net.vmin.min()),
        "vmax_pu": float(net.vmax.max()),
        "loads": int(net.n_load),
        "series": None if loaded.series is None else loaded.series.source,
        "notes": list(loaded.notes),
    }


class RunStore:
    """One run folder (see the module docstring). Use as a context manager: the lock is
    held inside the `with` block."""

    def __init__(self, out: Path, say=print):
        self.out = check_out_dir(Path(out))
        self.tasks_dir = self.out / "tasks"
        self.lock = self.out / ".lock"
        self.say = say
        self.manifest: dict = {}

    # ----- lock -------------------------------------------------------------------------
    def __enter__(self) -> "RunStore":
        me = f"{os.getpid()} {socket.gethostname()}\n"
        while True:
            try:
                fd = os.open(self.lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                text = self.lock.read_text().split()
                pid = int(text[0]) if text and text[0].isdigit() else -1
                host = text[1] if len(text) > 1 else socket.gethostname()
                if pid > 0 and (host != socket.gethostname() or _alive(pid)):
                    raise InputError(
                        f"{self.out} is in use by another run (PID {pid} on {host}); wait for it, or "
                        f"delete {self.lock} if that run is gone"
                    ) from None
                self.say(f"note: taking over the lock of a run that is gone (PID {pid})")
                self.lock.unlink(missing_ok=True)
                continue
            except OSError as exc:
                raise InputError(f"--out {self.out} is not writable ({exc.strerror})") from None
            with os.fdopen(fd, "w") as fh:
                fh.write(me)
            return self

    def __exit__(self, *exc) -> None:
        self.lock.unlink(missing_ok=True)

    # ----- manifest ---------------------------------------------------------------------
    def open(self, config: StudyConfig, period: Period, tasks: list[Task], command: list[str], fresh: bool) -> set[str]:
        """Check the folder against `config`, write the manifest; returns the ids of the
        tasks already finished (resume)."""
        path = self.out / "manifest.json"
        digest = config.digest()
        if path.exists() and not fresh:
            import json

            try:
                old = json.loads(path.read_text())
            except ValueError:
                raise InputError(f"{path} is not a run manifest; use --fresh to start over") from None
            if old.get("config_digest") != digest:
                prev = old.get("config", {})
                now = config.as_dict()
                diff = sorted(k for k in now if k not in LABEL_FIELDS and prev.get(k) != now[k])
                raise InputError(
                    f"{self.out} holds a run of another configuration (differs in: {', '.join(diff) or '?'}); "
                    "use --fresh to discard it, or another --out"
                )
        if fresh:
            self._discard()
        self.tasks_dir.mkdir(exist_ok=True)
        for stale in (*self.out.glob(".*.tmp"), *self.tasks_dir.glob(".*.tmp")):  # left by a killed run
            stale.unlink()
        done = {t.id for t in tasks if (self.out / t.file).exists()}
        self.manifest = {
            "schema": SCHEMA,
            "opfbench_version": _version(),
            "git_commit": _git_commit(),
            "command": command,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "config": config.as_dict(),
            "config_digest": digest,
            "period": period.as_dict(),
            "data_sources": list(period.sources),
            "versions": _versions(),
            "machine": {"cores": os.cpu_count(), "platform": platform.platform()},
            "cases": {case: _case_info(case) for case in config.cases},
            "tasks": [t.as_dict() | {"done": t.id in done, "wall_s": None} for t in tasks],
            "timings": {"wall_s": None, "workers": None, "scheduler": None},
        }
        write_json(path, self.manifest)
        return done

    def _discard(self) -> None:
        for name in RUN_FILES:
            (self.out / name).unlink(missing_ok=True)
        if self.tasks_dir.is_dir():
            for f in self.tasks_dir.glob("*.parquet"):
                f.unlink()

    def finish_manifest(self, wall_s: float | None, workers: int, scheduler: str | None, task_wall: dict) -> None:
        for t in self.manifest["tasks"]:
            t["done"] = (self.out / t["file"]).exists()
            t["wall_s"] = task_wall.get(t["id"], t["wall_s"])
        self.manifest["timings"] = {"wall_s": wall_s, "workers": workers, "scheduler": scheduler} | _peak_rss_mb()
        write_json(self.out / "manifest.json", self.manifest)

    # ----- checkpoints --------------------------------------------------------------------
    def save(self, result: TaskOutput) -> None:
        """Write a finished task atomically (its side files first, the main file last)."""
        base = self.out / result.task.file
        for name, frame in (result.detail | {"summary": result.summary}).items():
            _write_parquet(base.with_suffix(f".{name}.parquet"), frame)
        _write_parquet(base, result.steps)

    # ----- assembly -----------------------------------------------------------------------
    def assembly(self, tasks: list[Task], detail: tuple[str, ...]) -> Assembly:
        """The run's tables, assembled from the task files of `tasks` as they are written."""
        return Assembly(self.out, tasks, detail)


class Assembly:
    """steps.parquet (+ the detail tables) and summary.csv from the task files, streamed in
    the planned order while the run goes on: `advance` adds every next task whose file
    is written (call it after each), `finish` adds the rest and commits, `abort` drops
    the temporary files. The tables go through as arrow tables, never pandas."""

    def __init__(self, out: Path, tasks: list[Task], detail: tuple[str, ...]):
        self.out, self.tasks, self.added = out, tasks, 0
        self.writers = {name: _AtomicParquet(out / f"{name}.parquet") for name in ("steps", *detail)}
        self.partials: list[pd.DataFrame] = []
        self.order: list[tuple] = []

    def advance(self) -> None:
        while self.added < len(self.tasks) and (self.out / self.tasks[self.added].file).exists():
            base = self.out / self.tasks[self.added].file
            for name, writer in self.writers.items():
                writer.write(pq.read_table(base if name == "steps" else base.with_suffix(f".{name}.parquet")))
            partial = pd.read_parquet(base.with_suffix(".summary.parquet"))
            self.partials.append(partial)
            self.order.extend(map(tuple, partial[KEYS].itertuples(index=False)))
            self.added += 1

    def finish(self) -> pd.DataFrame:
        """Commit the tables once every task is added; returns the summary."""
        self.advance()
        if self.added < len(self.tasks):
            raise RuntimeError(f"task {self.tasks[self.added].id} has no file in {self.out / 'tasks'}")
        for w in self.writers.values():
            w.commit()
        summary = summarize(self.partials, list(dict.fromkeys(self.order)))
        buf = io.StringIO()
        summary.to_csv(buf, index=False, float_format="%.6g")
        write_atomic(self.out / "summary.csv", buf.getvalue())
        return summary

    def abort(self) -> None:
        for w in self.writers.values():
            w.abort()


def _peak_rss_mb() -> dict:
    """Peak resident memory (MiB) of this process and of the largest finished child
    process (local Dask workers, once shut down)."""
    import resource

    kib = {"peak_rss_mb": resource.RUSAGE_SELF, "worker_peak_rss_mb": resource.RUSAGE_CHILDREN}
    return {key: resource.getrusage(who).ru_maxrss / 1024 for key, who in kib.items()}


def _version() -> str:
    from opfbench import __version__

    return __version__


def _arrow(frame: pd.DataFrame | pa.Table) -> pa.Table:
    """The frame as an arrow table whose categorical columns are plain strings (the files
    hold text; categoricals only make building and writing the long tables fast)."""
    table = frame if isinstance(frame, pa.Table) else pa.Table.from_pandas(frame, preserve_index=False)
    fields = [pa.field(f.name, f.type.value_type) if pa.types.is_dictionary(f.type) else f for f in table.schema]
    return table.cast(pa.schema(fields)) if fields != list(table.schema) else table


def _write_parquet(path: Path, frame: pd.DataFrame) -> None:
    buf = io.BytesIO()
    pq.write_table(_arrow(frame), buf)
    write_atomic(path, buf.getvalue())


class _AtomicParquet:
    """A parquet file written table by table into a temporary file, renamed on commit."""

    def __init__(self, path: Path):
        self.path, self.tmp = path, path.with_name(f".{path.name}.{os.getpid()}.tmp")
        self.writer: pq.ParquetWriter | None = None

    def write(self, frame: pd.DataFrame | pa.Table) -> None:
        table = _arrow(frame)
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.tmp, table.schema)
        self.writer.write_table(table.cast(self.writer.schema))

    def commit(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None
            os.replace(self.tmp, self.path)

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        self.tmp.unlink(missing_ok=True)
