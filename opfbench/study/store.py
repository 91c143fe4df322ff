"""The study folder of any task family (`study.engine`): lock, manifest, one checkpoint per
finished task (layout and fields: docs/CONTRACTS.md).

- Lock: `.lock` holds the PID and host of the run using the folder; a second run is
  refused while that process lives; a lock left by a dead process is taken over, with a
  note.
- Manifest (`manifest.json`, the one manifest writer): the family's config and its
  digest, the hash of each input's data, versions, machine, the task list with each
  task's full definition, timings. The same config on the same data resumes; another
  config, edited input data, another kind of folder or another manifest schema is
  refused (`--fresh` discards the previous run's files, and only those, where the kind
  matches). Opening a folder removes its previously assembled files first, so the folder
  never holds a mix of two runs' files.
- Checkpoints: `tasks/<id>.parquet` (the task's main table) with its other tables beside
  it (`tasks/<id>.<name>.parquet`), written side files first and each atomically, every
  file tagged with its task's definition hash (and the main one with every table's row
  count). A task counts as finished only if all of its files are there, readable, of its
  definition and of their recorded length: anything else — truncated, empty, another
  task's rows, a file missing — is recomputed, with a note. Checkpoint files of no task of
  this run are removed, with a note.
"""

from __future__ import annotations

import json
import os
import platform
import re
import shutil
import socket
import subprocess
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import pyarrow as pa
import pyarrow.parquet as pq

from opfbench.errors import InputError
from opfbench.folders import check_out_dir
from opfbench.jsonio import write_json
from opfbench.parquetio import arrow_table, write_parquet
from opfbench.study.engine import Task, TaskFamily, TaskOutput

SCHEMA = 2  # 2: kinds, task definitions and hashed ids, input data hashes
TASK_KEY = b"opfbench.task"  # a checkpoint file's metadata: its task's definition hash
ROWS_KEY = b"opfbench.rows"  # the main file's metadata: every table's row count (JSON)
_MAIN = re.compile(r"-[0-9a-f]{16}\.parquet$")


def finished_tasks(out: Path) -> int:
    """How many checkpoints (main files) the folder `out` holds."""
    return sum(bool(_MAIN.search(f.name)) for f in (Path(out) / "tasks").glob("*.parquet"))


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
    for name in ("numpy", "scipy", "pandas", "pyarrow", "numba", "casadi", "cvxpy", "clarabel", "dask", "distributed"):
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


def _peak_rss_mb() -> dict:
    """Peak resident memory (MiB) of this process and of the largest finished child
    process (a local Dask cluster's workers say theirs before they shut down: the engine
    passes that figure instead)."""
    import resource

    kib = {"peak_rss_mb": resource.RUSAGE_SELF, "worker_peak_rss_mb": resource.RUSAGE_CHILDREN}
    return {key: resource.getrusage(who).ru_maxrss / 1024 for key, who in kib.items()}


def _version() -> str:
    from opfbench import __version__

    return __version__


def side_file(task: Task, name: str, tables: tuple[str, ...]) -> str:
    """The checkpoint file of the task's table `name` (relative to the folder)."""
    return task.file if name == tables[0] else task.file.removesuffix(".parquet") + f".{name}.parquet"


class RunStore:
    """One study folder (see the module docstring). Use as a context manager: the lock is
    held inside the `with` block. `note` prints what the user should know."""

    def __init__(self, out: Path, note=print):
        self.out = check_out_dir(Path(out))
        self.tasks_dir = self.out / "tasks"
        self.lock = self.out / ".lock"
        self.note = note
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
                self.note(f"note: taking over the lock of a run that is gone (PID {pid})")
                self.lock.unlink(missing_ok=True)
                continue
            except OSError as exc:
                raise InputError(f"--out {self.out} is not writable ({exc.strerror})") from None
            with os.fdopen(fd, "w") as fh:
                fh.write(me)
            return self

    def __exit__(self, *exc) -> None:
        self.release()

    def release(self) -> None:
        self.lock.unlink(missing_ok=True)

    # ----- manifest ---------------------------------------------------------------------
    def open(self, family: TaskFamily, command: list[str], fresh: bool) -> set[str]:
        """Check the folder against the family's config and data, clear what a previous
        run assembled, write the manifest; returns the ids of the tasks whose checkpoints
        are kept (resume)."""
        path = self.out / "manifest.json"
        part = self.check(family, fresh)
        if self.tasks_dir.exists() and not self.tasks_dir.is_dir():
            raise InputError(f"{self.tasks_dir} is not a folder (a study keeps its checkpoints there); move it away")
        for name in family.outputs:  # a previous run's assembled files: never mixed with this run's
            _remove(self.out / name)
        if fresh:
            _remove(path)
            for f in self.tasks_dir.glob("*.parquet"):
                _remove(f)
        self.tasks_dir.mkdir(exist_ok=True)
        for stale in (*self.out.glob(".*.tmp"), *self.tasks_dir.glob(".*.tmp")):  # left by a killed run
            _remove(stale)
        done = self._checkpoints(family)
        self.manifest = {
            "schema": SCHEMA,
            "kind": family.kind,
            "opfbench_version": _version(),
            "git_commit": _git_commit(),
            "command": command,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            **part,
            "versions": _versions(),
            "machine": {"cores": os.cpu_count(), "platform": platform.platform()},
            "tasks": [t.as_dict() | {"done": t.id in done, "wall_s": None} for t in family.tasks],
            "timings": {"wall_s": None, "workers": None, "scheduler": None},
        }
        write_json(path, self.manifest)
        return done

    def check(self, family: TaskFamily, fresh: bool) -> dict:
        """What `open` checks before it touches the folder — a manifest of another kind,
        version, configuration or data (without `fresh`) — InputError naming it; returns
        the family's part of the manifest. A caller with work to do before the run (a
        run's training) calls it first."""
        path = self.out / "manifest.json"
        part = family.manifest()
        if not path.exists():
            self._check_empty(family)
        old = self._previous(path, family.kind, fresh) if path.exists() else None
        if old is not None and not fresh:
            self._check_resume(old, part, family)
        return part

    def _check_empty(self, family: TaskFamily) -> None:
        """A folder without a manifest holds nothing but what a run of `family` writes
        (its checkpoints, outputs and side entries, hidden files): a run never writes
        among other files (and `--fresh` never removes one of them)."""
        own = {"tasks", *family.outputs, *family.side_entries}
        foreign = sorted(p.name for p in self.out.iterdir() if p.name not in own and not p.name.startswith("."))
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise InputError(
                f"--out {self.out} holds files of no opfbench {family.kind} ({shown}): give a new or empty folder, "
                "or the folder of an earlier run to resume it"
            )

    def _previous(self, path: Path, kind: str, fresh: bool) -> dict | None:
        """The folder's manifest (None: unreadable, to be discarded with `fresh`);
        InputError if it is not one (without `fresh`) or of another kind."""
        try:
            old = json.loads(path.read_bytes().decode("utf-8"))
        except (OSError, ValueError, RecursionError):
            old = None
        if not isinstance(old, dict):
            if fresh:
                return None
            raise InputError(f"{path} is not a manifest opfbench wrote; use --fresh to start over, or another --out")
        # schema 1 wrote no kind: its fault folders have an operating point
        theirs = old.get("kind") or ("fault" if "operating_point" in old else "run")
        if theirs != kind:
            raise InputError(f"{self.out} holds a {theirs} folder; give the {kind} study a folder of its own (another --out)")
        return old

    def _check_resume(self, old: dict, part: dict, family: TaskFamily) -> None:
        if old.get("schema") != SCHEMA:
            raise InputError(
                f"{self.out} holds a run written by another opfbench version (manifest schema {old.get('schema')!r}, "
                f"this one writes {SCHEMA}); use --fresh to discard it, or another --out"
            )
        if old.get("config_digest") != part["config_digest"]:
            prev = _object(old.get("config"))
            now = part["config"]
            diff = sorted(k for k in now if k not in family.label_fields and prev.get(k) != now[k])
            raise InputError(
                f"{self.out} holds a run of another configuration (differs in: {', '.join(diff) or '?'}); "
                "use --fresh to discard it, or another --out"
            )
        before = _object(old.get("data_sha256"))
        for name, sha in part["data_sha256"].items():
            if before.get(name) != sha:
                raise InputError(
                    f"{self.out}: the data of {name} changed since this run began (sha256 {str(before.get(name))[:12]}… → "
                    f"{sha[:12]}…); its finished tasks are of the old data: use --fresh to discard them, or restore "
                    "the old data"
                )

    def _checkpoints(self, family: TaskFamily) -> set[str]:
        """The planned tasks whose checkpoints are whole and of their definition; the
        files of the others (and of no planned task) are removed, with a note."""
        done: set[str] = set()
        mine: set[str] = set()
        for task in family.tasks:
            files = {name: self.out / side_file(task, name, family.tables) for name in family.tables}
            mine.update(f.name for f in files.values())
            if not files[family.tables[0]].exists():
                continue
            problem = _damage(task, files, family.columns)
            if problem is None:
                done.add(task.id)
                continue
            self.note(f"note: {task.file} {problem}: recomputing that task")
            for f in files.values():
                _remove(f)
        foreign = [f for f in self.tasks_dir.glob("*.parquet") if f.name not in mine]
        if foreign:
            self.note(f"note: removed {len(foreign)} checkpoint file(s) of no task of this run from {self.tasks_dir}")
            for f in foreign:
                _remove(f)
        return done

    def finish_manifest(self, wall_s: float | None, workers: int, scheduler: str | None, task_wall: dict, extra: dict) -> None:
        for t in self.manifest["tasks"]:
            t["done"] = (self.out / t["file"]).exists()
            t["wall_s"] = task_wall.get(t["id"], t["wall_s"])
        timings = {"wall_s": wall_s, "workers": workers, "scheduler": scheduler}
        self.manifest["timings"] = timings | (_peak_rss_mb() if wall_s is not None else {}) | extra
        write_json(self.out / "manifest.json", self.manifest)

    # ----- checkpoints --------------------------------------------------------------------
    def save(self, result: TaskOutput, tables: tuple[str, ...]) -> dict[str, pa.Table]:
        """Write a finished task atomically (its side files first, the main file last);
        returns the tables as written (arrow)."""
        task = result.task
        tag = {TASK_KEY: task.digest.encode()}
        rows = json.dumps({name: len(result.tables[name]) for name in tables}).encode()
        written = {}
        for name in (*tables[1:], tables[0]):
            meta = tag | {ROWS_KEY: rows} if name == tables[0] else tag
            written[name] = arrow_table(result.tables[name], meta)
            write_parquet(self.out / side_file(task, name, tables), written[name])
        return written

    def read(self, task: Task, tables: tuple[str, ...]) -> dict[str, pa.Table]:
        """A finished task's tables, as arrow tables."""
        return {name: pq.read_table(self.out / side_file(task, name, tables)) for name in tables}


def _remove(path: Path) -> None:
    """Remove the file (or a folder standing where one of the study's files belongs)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _object(value: object) -> dict:
    return value if isinstance(value, dict) else {}


def _damage(task: Task, files: dict[str, Path], columns: Callable[[str], list[str]]) -> str | None:
    """Why the checkpoint `files` (table name → file, the main one first) are not the
    finished task `task` with each table's `columns`, or None."""
    rows: object = None
    for i, (name, path) in enumerate(files.items()):
        if not path.exists():
            return f"is partly missing (no {path.name})"
        if not path.is_file():
            return f"is partly unreadable ({path.name} is not a file)"
        if path.stat().st_size == 0:
            return "is empty" if i == 0 else f"is partly empty ({path.name})"
        try:
            meta = pq.read_metadata(path)
        except (OSError, pa.ArrowException):
            return "is truncated or not a parquet file" if i == 0 else f"is partly unreadable ({path.name})"
        tags = meta.metadata or {}
        if tags.get(TASK_KEY) != task.digest.encode():
            return "holds another task's rows" if TASK_KEY in tags else "was not written as this task's checkpoint"
        if i == 0:
            try:
                rows = json.loads(tags.get(ROWS_KEY, b"null"))
            except ValueError:
                rows = None
        if not isinstance(rows, dict) or rows.get(name) != meta.num_rows:
            return f"is partly missing (rows of {path.name})"
        if meta.schema.names != columns(name):
            return f"has other columns than this version writes ({path.name})"
    return None
