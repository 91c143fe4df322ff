"""`python -m opfbench.bench all`: every registered benchmark, each in a fresh process,
`--repeats` times, and one record of their figures.

    python -m opfbench.bench all [--json] [--repeats N] [--only NAME …] [--out FILE] [--tree DIR]
    python -m opfbench.bench all --markdown [--record FILE] [--page FILE]

A record (JSON) holds `keys` — every numeric figure, flattened as `bench.key` (nested
tables joined by dots), the median over the repeats —, each bench's runs as printed, the
`guards` (key → the peer it is measured against, `check`), the machine (CPU, cores,
memory, package versions, load average before and after), the commit of the code that
ran (with `dirty` when its tracked files differ from it) and the date. Each bench runs
under `harness.py`, which times a fixed reference workload before and after it in the
same process (`calibration_ms`): the peer of keys that have none of their own. A bench
that fails is recorded with its message (and the exit status is 1); the others still run.

`--tree DIR` runs the benchmarks of another checkout (DIR first on PYTHONPATH, with this
environment's packages) — the before of a before-and-after; a bench that checkout lacks
is recorded as failed. `--markdown` writes the benchmark page (`docs/BENCHMARKS.md`) from a
record (default: the committed one, `docs/benchmarks.json`) and runs nothing.

ALL registers the benchmarks; a new bench module joins by adding its `Bench` (name, module,
options, guarded keys and their peers).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

import opfbench
from opfbench.errors import InputError
from opfbench.jsonio import dumps, write_atomic
from opfbench.timing import elapsed_ms, now

SCHEMA = 1
ROOT = Path(opfbench.__file__).resolve().parents[1]
RECORD = ROOT / "docs" / "benchmarks.json"  # the committed record
PAGE = ROOT / "docs" / "BENCHMARKS.md"  # generated from it
HARNESS = Path(__file__).resolve().with_name("harness.py")
CALIBRATION = "calibration_ms"
PACKAGES = ("numpy", "scipy", "numba", "clarabel", "cvxpy", "casadi", "pandas", "pandapower", "power-grid-model", "dask")


@dataclass(frozen=True)
class Bench:
    """One benchmark of `all`: `module` (`opfbench.bench.<module>`) run with `options`, its
    figures recorded as `name.key`; `guards`: key → peer key (both of this bench's
    figures, `calibration_ms` for the reference workload), lower is better for both."""

    name: str
    module: str
    options: tuple[str, ...] = ()
    guards: dict[str, str] = field(default_factory=dict)


ALL: tuple[Bench, ...] = (
    Bench("pf", "pf", (), {"single_ms": "pgm_batch_1440_ms", "batch_1440_ms": "pgm_batch_1440_ms"}),
    Bench("local", "local", (), {"voltvar_day_ms": CALIBRATION, "rules.lfma.wall_ms": CALIBRATION}),
    Bench(
        "opf",
        "opf",
        (),
        {
            "acopf_step_ms": "pandapower_runopp_ms",
            "socp_step_ms": "pandapower_runopp_ms",
            "ipopt_ms": "pandapower_runopp_ms",
            "mv_acopf_step_ms": "mv_pandapower_runopp_ms",
            "mv_socp_step_ms": "mv_pandapower_runopp_ms",
            "kkt_mv_iteration_us": "kkt_mv_ldl_us",  # Clarabel's iteration against the LDLᵀ it needs (bench.kkt)
        },
    ),
    Bench("fault", "fault", (), {"sim_ms": "andes_sim_ms", "study_s": CALIBRATION}),
    Bench("run", "run", ("--repeats", "1"), {"day_s": CALIBRATION}),
    Bench("suite", "run", ("--suite", "--repeats", "1"), {"suite_year_est_min": CALIBRATION, "suite_week_s": CALIBRATION}),
    Bench("learned", "learned", (), {"learned_fit_s": CALIBRATION}),
    Bench(  # cases.0: paper33's day (the band never binds), cases.1: a week of 1-MV-rural (it binds)
        "frontier",
        "frontier",
        (),
        {"cases.0.frontier_ms": "cases.0.acopf_ms", "cases.1.frontier_extra_ms": "cases.1.acopf_ms"},
    ),
    Bench(  # the three-phase flow and rules against OpenDSS in the same process (issue 29)
        "unbalanced",
        "unbalanced",
        ("--large",),
        {
            "eulv_day_ms": "eulv_dss_daily_ms",
            "eulv_volt_var_day_ms": "eulv_no_action_day_ms",
            "ieee8500_pf_ms": CALIBRATION,
            "ieee8500_batch96_ms": CALIBRATION,
            "ieee8500_opf_solve_ms": CALIBRATION,
        },
    ),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=1, help="runs of each bench, each in a fresh process (medians kept)")
    parser.add_argument("--only", nargs="+", choices=[b.name for b in ALL], default=None, help="these benches only")
    parser.add_argument("--out", type=Path, default=Path("reports/bench/record.json"), help="the record's file")
    parser.add_argument("--tree", type=Path, default=None, help="run another checkout's benchmarks (DIR on PYTHONPATH)")
    parser.add_argument("--markdown", action="store_true", help="write the benchmark page from --record; run nothing")
    parser.add_argument("--record", type=Path, default=RECORD, help=f"the record --markdown reads (default {RECORD})")
    parser.add_argument("--page", type=Path, default=PAGE, help=f"the page --markdown writes (default {PAGE})")


def flatten(figures: dict, prefix: str = "") -> dict[str, float]:
    """The numeric scalars of `figures` as {"a.b": value}: nested dicts joined by dots, a
    list of dicts by position ("cases.0.x"); other lists, text, booleans and None left out."""
    out: dict[str, float] = {}
    for key, value in figures.items():
        name = f"{prefix}{key}"
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            value = {str(i): v for i, v in enumerate(value)}
        if isinstance(value, dict):
            out |= flatten(value, f"{name}.")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            out[name] = float(value)
    return out


def medians(runs: list[dict]) -> dict[str, float]:
    """Per key, the median over the runs that have it."""
    values: dict[str, list[float]] = {}
    for figures in runs:
        for key, value in flatten(figures).items():
            values.setdefault(key, []).append(value)
    return {key: statistics.median(v) for key, v in values.items()}


def _git(tree: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def commit_of(tree: Path) -> dict:
    """{"commit": sha or None, "dirty": tracked files differ from it (None: unknown)}."""
    sha = _git(tree, "rev-parse", "HEAD")
    status = _git(tree, "status", "--porcelain", "--untracked-files=no") if sha else None
    return {"commit": sha, "dirty": None if status is None else bool(status)}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    """What the figures depend on besides the code."""
    versions: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") if hasattr(os, "sysconf") else None
    return {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "memory_gib": None if memory is None else round(memory / 2**30, 1),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "packages": versions,
    }


def run_bench(bench: Bench, tree: Path | None) -> tuple[dict | None, str | None, float]:
    """(figures, error message, wall s) of one run of `bench` in a fresh process."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    start = now()
    done = subprocess.run(
        [sys.executable, "-P", str(HARNESS), bench.module, *bench.options], capture_output=True, text=True, env=env
    )
    wall = elapsed_ms(start) / 1e3
    if done.returncode:
        lines = [line for line in done.stderr.strip().splitlines() if line.strip()]
        return None, lines[-1] if lines else f"exit status {done.returncode}", wall
    import json

    return json.loads(done.stdout.strip().splitlines()[-1]), None, wall


def make_record(benches: tuple[Bench, ...], repeats: int, tree: Path | None, progress=print) -> dict:
    """Run `benches` `repeats` times each (module docstring) and return the record."""
    started = datetime.now(timezone.utc)
    load_before = list(os.getloadavg())
    record: dict = {
        "schema": SCHEMA,
        "date": started.isoformat(timespec="seconds"),
        **commit_of(tree or ROOT),
        "machine": machine(),
        "repeats": repeats,
        "benches": {},
        "keys": {},
        "guards": {},
    }
    for bench in benches:
        runs: list[dict] = []
        errors: list[str] = []
        walls: list[float] = []
        for i in range(repeats):
            progress(f"bench {bench.name} ({i + 1}/{repeats}) …")
            figures, error, wall = run_bench(bench, tree)
            walls.append(wall)
            if figures is None:
                errors.append(error or "no figures")
                break  # the same failure again would only cost time
            runs.append(figures)
        record["benches"][bench.name] = {
            "module": bench.module,
            "options": list(bench.options),
            "runs": runs,
            "errors": errors,
            "wall_s": walls,
        }
        record["keys"] |= {f"{bench.name}.{key}": value for key, value in medians(runs).items()}
        record["guards"] |= {f"{bench.name}.{key}": f"{bench.name}.{peer}" for key, peer in bench.guards.items()}
    record["machine"]["load_average"] = {"before": load_before, "after": list(os.getloadavg())}
    return record


def read_record(path: Path) -> dict:
    """A record file; InputError naming it when it is missing or not a record."""
    import json

    try:
        record = json.loads(Path(path).read_text())
    except OSError as exc:
        raise InputError(f"benchmark record {path}: cannot be read ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise InputError(f"benchmark record {path}: not JSON ({exc})") from None
    if not isinstance(record, dict) or record.get("schema") != SCHEMA:
        raise InputError(f"benchmark record {path}: not a record of schema {SCHEMA} (`python -m opfbench.bench all` writes one)")
    for name, kind in (("keys", dict), ("guards", dict), ("benches", dict)):
        if not isinstance(record.get(name), kind):
            raise InputError(f"benchmark record {path}: its {name!r} is missing or not an object")
    bad = [k for k, v in record["keys"].items() if not isinstance(v, (int, float)) or isinstance(v, bool)]
    if bad:
        raise InputError(f"benchmark record {path}: key {bad[0]!r} is not a number")
    return record


def run(args: argparse.Namespace) -> dict:
    if args.markdown:
        from opfbench.bench.page import write_page

        return {"page": str(write_page(read_record(args.record), args.page, args.record))}
    if args.repeats < 1:
        raise InputError(f"--repeats must be ≥ 1, got {args.repeats}")
    if args.tree is not None and not (args.tree / "opfbench" / "bench").is_dir():
        raise InputError(f"--tree {args.tree}: no opfbench/bench there (a checkout of opfbench)")
    benches = tuple(b for b in ALL if args.only is None or b.name in args.only)
    record = make_record(benches, args.repeats, args.tree, progress=lambda text: print(text, file=sys.stderr))
    write_atomic(args.out, dumps(record) + "\n")
    return record


def exit_code(figures: dict) -> int:
    """1 when a bench failed, else 0."""
    return int(any(b["errors"] for b in figures.get("benches", {}).values()))


def print_table(f: dict) -> None:
    if "page" in f:
        print(f"wrote {f['page']}")
        return
    print(
        f"benchmark record: commit {f['commit'] or 'unknown'}{' (dirty)' if f['dirty'] else ''}, {f['date']}, {f['repeats']} run(s) each"
    )
    for name, bench in f["benches"].items():
        status = "; ".join(bench["errors"]) if bench["errors"] else f"{len(bench['runs'])} run(s)"
        print(f"  {name:8s} {status}")
        for key in (k for k in f["guards"] if k.startswith(f"{name}.")):
            value = f["keys"].get(key)
            print(f"    {key:32s} {'—' if value is None else f'{value:.4g}'}")
