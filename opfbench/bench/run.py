"""Benchmark: the main job end to end — `opfbench run` with its default grid on the paper
day, wall time including start-up (a fresh process each), on 1 worker and on 2 worker
processes, alternately, `--repeats` times (default 3): `day_s` and `day_s_1worker` are
the medians (a shared 2-core machine varies by ±10 % from run to run), every run's time
is kept in `day_s_runs` / `day_s_1worker_runs`; with `--year` also the year 2016 at 15 min
on 2 workers, once. Also checks that the paper-day tables are identical (timing columns
aside).

    python -m opfbench.bench run [--json] [--year] [--repeats N]

Targets (issue 11): paper day ≤ 20 s and year ≤ 300 s on 2 cores.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

from opfbench.timing import elapsed_ms, now

TARGET_DAY_S = 20.0
TARGET_YEAR_S = 300.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--year", action="store_true", help="also time the year 2016 at 15 min on 2 workers")
    parser.add_argument("--repeats", type=int, default=3, help="paper-day runs per worker count (median reported)")


def _timed(out: Path, *args: str) -> float:
    start = now()
    subprocess.run(
        [sys.executable, "-m", "opfbench", "run", "--quiet", "--out", str(out), *args], check=True, stdout=subprocess.DEVNULL
    )
    return elapsed_ms(start) / 1e3


def _same(a: Path, b: Path) -> bool:
    drop = ["wall_ms", "solver_ms"]
    return pd.read_parquet(a / "steps.parquet").drop(columns=drop).equals(pd.read_parquet(b / "steps.parquet").drop(columns=drop))


def run(args: argparse.Namespace | None = None) -> dict:
    repeats = max(1, args.repeats) if args is not None else 3
    with tempfile.TemporaryDirectory(prefix="opfbench-bench-run-") as tmp:
        root = Path(tmp)
        runs: dict[int, list[float]] = {1: [], 2: []}
        for i in range(repeats):
            for workers in (1, 2):
                runs[workers].append(_timed(root / f"day{workers}-{i}", "--workers", str(workers)))
        year = _timed(root / "year", "--period", "year", "--workers", "2") if args is not None and args.year else None
        identical = all(_same(root / "day1-0", root / f"day{w}-{i}") for w in (1, 2) for i in range(repeats))
    day_1, day_2 = statistics.median(runs[1]), statistics.median(runs[2])
    return {
        "day_s_1worker": day_1,
        "day_s": day_2,
        "speedup": day_1 / day_2,
        "year_s": year,
        "day_s_1worker_runs": runs[1],
        "day_s_runs": runs[2],
        "repeats": repeats,
        "identical_1_vs_2_workers": identical,
        "target_day_s": TARGET_DAY_S,
        "target_year_s": TARGET_YEAR_S,
    }


def _runs(times: list[float]) -> str:
    return ", ".join(f"{t:.1f}" for t in times)


def print_table(f: dict) -> None:
    print("opfbench run, default grid, wall time including start-up")
    print(f"  paper day, 1 worker : {f['day_s_1worker']:8.1f} s median of {f['repeats']} ({_runs(f['day_s_1worker_runs'])})")
    print(
        f"  paper day, 2 workers: {f['day_s']:8.1f} s median of {f['repeats']} ({_runs(f['day_s_runs'])}); speed-up "
        f"{f['speedup']:.2f}×, target ≤ {f['target_day_s']:.0f} s; tables identical: {f['identical_1_vs_2_workers']}"
    )
    if f["year_s"] is not None:
        print(f"  year 15 min, 2 workers: {f['year_s']:8.1f} s  (target ≤ {f['target_year_s']:.0f} s)")
