"""Benchmark: the main job end to end — `opfbench run` with its default grid on the paper
day, wall time including start-up (a fresh process each), on 1 worker and on 2 worker
processes; with `--year` also the year 2016 at 15 min on 2 workers. Also checks that the
two paper-day tables are identical (timing columns aside).

    python -m opfbench.bench run [--json] [--year]

Targets (issue 11): paper day ≤ 20 s and year ≤ 300 s on 2 cores.
"""

from __future__ import annotations

import argparse
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


def _timed(out: Path, *args: str) -> float:
    start = now()
    subprocess.run([sys.executable, "-m", "opfbench", "run", "--quiet", "--out", str(out), *args], check=True,
                   stdout=subprocess.DEVNULL)
    return elapsed_ms(start) / 1e3


def _same(a: Path, b: Path) -> bool:
    drop = ["wall_ms", "solver_ms"]
    return pd.read_parquet(a / "steps.parquet").drop(columns=drop).equals(pd.read_parquet(b / "steps.parquet").drop(columns=drop))


def run(args: argparse.Namespace | None = None) -> dict:
    with tempfile.TemporaryDirectory(prefix="opfbench-bench-run-") as tmp:
        root = Path(tmp)
        day_1 = _timed(root / "day1", "--workers", "1")
        day_2 = _timed(root / "day2", "--workers", "2")
        year = _timed(root / "year", "--period", "year", "--workers", "2") if args is not None and args.year else None
        identical = _same(root / "day1", root / "day2")
    return {"day_s_1worker": day_1, "day_s": day_2, "speedup": day_1 / day_2, "year_s": year,
            "identical_1_vs_2_workers": identical, "target_day_s": TARGET_DAY_S, "target_year_s": TARGET_YEAR_S}


def print_table(f: dict) -> None:
    print("opfbench run, default grid, wall time including start-up")
    print(f"  paper day, 1 worker : {f['day_s_1worker']:8.1f} s")
    print(f"  paper day, 2 workers: {f['day_s']:8.1f} s  (speed-up {f['speedup']:.2f}×, target ≤ {f['target_day_s']:.0f} s; "
          f"tables identical: {f['identical_1_vs_2_workers']})")
    if f["year_s"] is not None:
        print(f"  year 15 min, 2 workers: {f['year_s']:8.1f} s  (target ≤ {f['target_year_s']:.0f} s)")
