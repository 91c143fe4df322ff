"""Benchmark: the main job end to end — `opfbench run` with its default grid on the paper
day, wall time including start-up (a fresh process each), on 1 worker and on 2 worker
processes, alternately, `--repeats` times (default 3): `day_s` and `day_s_1worker` are
the medians (a shared 2-core machine varies by ±10 % from run to run), every run's time
is kept in `day_s_runs` / `day_s_1worker_runs`; with `--year` also the year 2016 at 15 min
on 2 workers, once. Also checks that the paper-day tables are identical (timing columns
aside).

    python -m opfbench.bench run [--json] [--year] [--repeats N]
    python -m opfbench.bench run --suite [--json] [--repeats N]
    python -m opfbench.bench run --suite --year [--reference DIR] [--out DIR] [--json]

Targets (issue 11): paper day ≤ 20 s and year ≤ 300 s on 2 cores.

`--suite` times the field suite instead (`opfbench run --suite simbench`: the ten SimBench
LV/MV grids on their own profiles, every strategy, k ∈ {0, 0.4}, every night mode and
forecast, 2 workers, no detail tables): one step (`suite_step_s`: start-up, reading the
grids, building the solvers, the report — what a run pays once) and the week 2016-06-20..27 at 15 min
(`suite_week_s`), each the median of `--repeats` runs (alternating; every week's in
`suite_week_s_runs`); the year is extrapolated as the one-step run plus 52.3 × the week's
cost beyond it (`suite_year_est_min`). Target (issue 33): the suite's year ≤ 10 minutes on
2 cores (issue 20's was 30).

`--suite --year` runs the suite's year itself, once, on 2 workers (`suite_year_s`, its CPU
`suite_year_cpu_s`), and with `--reference DIR` compares it with another run of the same
grid (e.g. by the code before a change: the slow reference): per configuration the certified
share and the not-settled count must be the same (`vs_reference` lists any that are not)
and the energies' largest relative difference is reported — against a reference run that
was stopped, on the tasks it finished (`compare_runs`); `--out DIR` keeps the year's
folder. On a machine shared with other jobs the wall time waits for them: the CPU time of
each run and its worker processes is reported beside (`suite_step_cpu_s`,
`suite_week_cpu_s`, the year extrapolated the same way `suite_year_est_cpu_h`; with two
workers busy throughout, an unshared machine's wall time is about half of it), and the
load average at the end (`load_average_1min`).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

from opfbench.errors import InputError
from opfbench.timing import elapsed_ms, now

TARGET_DAY_S = 20.0
TARGET_YEAR_S = 300.0
TARGET_SUITE_YEAR_MIN = 10.0  # issue 33 (issue 20's was 30)
SUITE_WEEK = "2016-06-20T00:00..2016-06-27T00:00"
SUITE_STEP = "2016-06-20T00:00..2016-06-20T00:15"
# --no-detail: the one-step run writes the same tables as the week (by default a period of
# ≤ 2 days also writes every DER's Q, which its report plots — a cost the week does not pay,
# which made the year's extrapolation optimistic by ~5 s × 52)
SUITE_GRID = ("--suite", "simbench", "--k", "0", "0.4", "--workers", "2", "--no-detail")
YEAR_STEPS, WEEK_STEPS = 35136, 672


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--year", action="store_true", help="also time the year 2016 at 15 min on 2 workers (with --suite: the suite's year)"
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="paper-day runs per worker count, or --suite step and week runs (median reported)"
    )
    parser.add_argument("--suite", action="store_true", help="time the field suite (SimBench) over a week instead")
    parser.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="with --suite --year: a run folder of the same grid by other code (the slow reference); its certified shares "
        "and not-settled counts must equal the year's",
    )
    parser.add_argument("--out", type=Path, default=None, help="with --suite --year: keep the year's run folder here")


def _children_cpu_s() -> float:
    """CPU time (user + system, s) of the finished child processes and their descendants."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _timed_cpu(out: Path, *args: str) -> tuple[float, float]:
    """(wall, CPU) seconds of one `opfbench run` in a fresh process (the CPU time of the
    process and its workers: on a machine shared with other jobs the wall time waits for
    them, the CPU time does not)."""
    start, cpu = now(), _children_cpu_s()
    done = subprocess.run(
        [sys.executable, "-m", "opfbench", "run", "--quiet", "--out", str(out), *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    if done.returncode:  # the run's own message, not only its exit code
        raise RuntimeError(f"opfbench run {' '.join(args)} failed ({done.returncode}):\n{done.stderr}")
    return elapsed_ms(start) / 1e3, _children_cpu_s() - cpu


def _timed(out: Path, *args: str) -> float:
    return _timed_cpu(out, *args)[0]


def _same(a: Path, b: Path) -> bool:
    drop = ["wall_ms", "solver_ms"]
    return pd.read_parquet(a / "steps.parquet").drop(columns=drop).equals(pd.read_parquet(b / "steps.parquet").drop(columns=drop))


def _year(step: float, week: float) -> float:
    """The year's estimate from the one-step run and the week (module docstring)."""
    return step + (week - step) * (YEAR_STEPS - 1) / (WEEK_STEPS - 1)


def run_suite(repeats: int = 1) -> dict:
    """The field suite: one step and a week on 2 workers, alternately `repeats` times
    (medians), the year extrapolated (module doc)."""
    runs: dict[str, list[tuple[float, float]]] = {"step": [], "week": []}
    with tempfile.TemporaryDirectory(prefix="opfbench-bench-suite-") as tmp:
        root = Path(tmp)
        _timed(root / "warm", *SUITE_GRID, "--period", SUITE_STEP)  # reads the grids once into the disk cache
        for i in range(repeats):
            runs["step"].append(_timed_cpu(root / f"step{i}", *SUITE_GRID, "--period", SUITE_STEP))
            runs["week"].append(_timed_cpu(root / f"week{i}", *SUITE_GRID, "--period", SUITE_WEEK))
        tasks = len(
            pd.read_parquet(root / "week0" / "steps.parquet").groupby(["case", "strategy", "k", "night_mode", "forecast"])
        )
    step, week = (statistics.median(t for t, _ in runs[name]) for name in ("step", "week"))
    step_cpu, week_cpu = (statistics.median(c for _, c in runs[name]) for name in ("step", "week"))
    return {
        "suite_step_s": step,
        "suite_week_s": week,
        "suite_year_est_min": _year(step, week) / 60,
        "suite_step_cpu_s": step_cpu,
        "suite_week_cpu_s": week_cpu,
        "suite_year_est_cpu_h": _year(step_cpu, week_cpu) / 3600,
        "suite_week_s_runs": [t for t, _ in runs["week"]],
        "suite_week_cpu_s_runs": [c for _, c in runs["week"]],
        "suite_step_s_runs": [t for t, _ in runs["step"]],
        "repeats": repeats,
        "load_average_1min": os.getloadavg()[0],
        "suite_configurations": tasks,
        "suite_week": SUITE_WEEK,
        "target_suite_year_min": TARGET_SUITE_YEAR_MIN,
    }


SAME_KEYS = ["case", "strategy", "k", "night_mode", "forecast"]


def _differing(ours: pd.DataFrame, ref: pd.DataFrame, column: str) -> list[str]:
    """The index entries (joined by "/") where `column` differs (NaN = NaN)."""
    a, b = ours[column], ref[column]
    same = (a == b) | (a.isna() & b.isna())
    return ["/".join(str(v) for v in key) for key in ours.index[~same.to_numpy()]]


def _energies(ours: pd.DataFrame, ref: pd.DataFrame) -> dict:
    energy = (ours.energy_kwh - ref.energy_kwh).abs() / ref.energy_kwh.abs()
    return {"energy_max_rel_diff": float(energy.max()), "identical_energies": bool((ours.energy_kwh == ref.energy_kwh).all())}


def _task_summaries(folder: Path, names: list[str]) -> pd.DataFrame:
    """The partial summaries of the tasks `names` (file stems) of a run folder, indexed by
    task and configuration."""
    parts = [pd.read_parquet(folder / "tasks" / f"{name}.summary.parquet").assign(task=name) for name in names]
    return pd.concat(parts, ignore_index=True).set_index(["task", *SAME_KEYS]).sort_index()


def compare_runs(run: Path, reference: Path) -> dict:
    """What must not change between two runs of the same grid: per configuration the
    certified share and the not-settled count — the configurations that differ are
    listed —, and how far the energies moved (largest relative difference).

    A finished reference (`summary.csv`) is compared configuration by configuration; a
    reference run that was stopped (no summary yet) task by task on the tasks it finished
    (`tasks/*.summary.parquet`, the same task ids as the run's: same definition), the
    certified count and not-settled count of each configuration in each task
    (`tasks_compared` of `reference_tasks`)."""
    if (reference / "summary.csv").is_file():
        ours, ref = (pd.read_csv(folder / "summary.csv").set_index(SAME_KEYS).sort_index() for folder in (run, reference))
        if not ours.index.equals(ref.index):
            raise InputError(f"{reference}: not a run of the same grid as {run} (its configurations differ)")
        return {
            "configurations": len(ours),
            "certified_share_differs": _differing(ours, ref, "certified_share"),
            "not_settled_differs": _differing(ours, ref, "not_settled_steps"),
        } | _energies(ours, ref)
    finished = sorted(f.name.removesuffix(".summary.parquet") for f in (reference / "tasks").glob("*.summary.parquet"))
    common = [name for name in finished if (run / "tasks" / f"{name}.summary.parquet").is_file()]
    if not common:
        raise InputError(f"{reference}: no summary.csv and no finished task of {run}'s grid (tasks/*.summary.parquet)")
    ours, ref = _task_summaries(run, common), _task_summaries(reference, common)
    if not ours.index.equals(ref.index):
        raise InputError(f"{reference}: not a run of the same grid as {run} (its tasks' configurations differ)")
    return {
        "configurations": len(ours.droplevel("task").index.unique()),
        "reference_tasks": len(finished),
        "tasks_compared": len(common),
        "task_configurations": len(ours),
        "certified_share_differs": _differing(ours, ref, "certified"),
        "not_settled_differs": _differing(ours, ref, "not_settled_steps"),
    } | _energies(ours, ref)


def run_suite_year(reference: Path | None, keep: Path | None) -> dict:
    """The field suite's year on 2 workers, run once and timed (wall and CPU), compared with
    a reference run of the same grid when given (`compare_runs`)."""
    if reference is not None and not (
        (reference / "summary.csv").is_file() or any((reference / "tasks").glob("*.summary.parquet"))
    ):
        raise InputError(
            f"--reference {reference}: no summary.csv and no finished task there (a folder of `opfbench run --suite simbench "
            "--period year`, finished or stopped)"
        )
    with tempfile.TemporaryDirectory(prefix="opfbench-bench-suite-year-") as tmp:
        out = keep if keep is not None else Path(tmp) / "year"
        _timed(Path(tmp) / "warm", *SUITE_GRID, "--period", SUITE_STEP)  # reads the grids once into the disk cache
        wall, cpu = _timed_cpu(out, *SUITE_GRID, "--period", "year", "--fresh")
        figures: dict = {
            "suite_year_s": wall,
            "suite_year_min": wall / 60,
            "suite_year_cpu_s": cpu,
            "load_average_1min": os.getloadavg()[0],
            "target_suite_year_min": TARGET_SUITE_YEAR_MIN,
        }
        if reference is not None:
            figures["reference"] = str(reference)
            figures["vs_reference"] = compare_runs(out, reference)
    return figures


def run(args: argparse.Namespace | None = None) -> dict:
    repeats = max(1, args.repeats) if args is not None else 3
    if args is not None and args.suite:
        return run_suite_year(args.reference, args.out) if args.year else run_suite(repeats)
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
    if "suite_year_s" in f:
        print(
            f"opfbench run --suite simbench --period year, k 0 and 0.4, 2 workers: {f['suite_year_min']:.1f} min "
            f"(target ≤ {f['target_suite_year_min']:.0f} min), CPU {f['suite_year_cpu_s'] / 60:.1f} min, "
            f"load average {f['load_average_1min']:.1f} at the end"
        )
        if "vs_reference" in f:
            v = f["vs_reference"]
            energies = "identical" if v["identical_energies"] else f"within {v['energy_max_rel_diff']:.1e} (relative)"
            scope = f"{v['configurations']} configurations"
            if "tasks_compared" in v:  # a stopped reference: its finished tasks
                scope += f" in the {v['tasks_compared']} tasks it finished ({v['task_configurations']} task configurations)"
            print(
                f"  against {f['reference']}: {scope}, certified share differs in {len(v['certified_share_differs'])}, "
                f"not-settled count in {len(v['not_settled_differs'])}; energies {energies}"
            )
        return
    if "suite_week_s" in f:
        print("opfbench run --suite simbench, k 0 and 0.4, every strategy, night mode and forecast, 2 workers")
        print(f"  one step       : {f['suite_step_s']:8.1f} s (start-up, grids, solvers, report)")
        print(f"  week {f['suite_week']}: {f['suite_week_s']:8.1f} s, {f['suite_configurations']} configurations")
        print(f"  year (estimate): {f['suite_year_est_min']:8.1f} min (target ≤ {f['target_suite_year_min']:.0f} min)")
        print(
            f"  CPU (run and workers): step {f['suite_step_cpu_s']:.1f} s, week {f['suite_week_cpu_s']:.1f} s, year "
            f"(estimate) {f['suite_year_est_cpu_h']:.2f} h; load average {f['load_average_1min']:.1f} at the end"
        )
        return
    print("opfbench run, default grid, wall time including start-up")
    print(f"  paper day, 1 worker : {f['day_s_1worker']:8.1f} s median of {f['repeats']} ({_runs(f['day_s_1worker_runs'])})")
    print(
        f"  paper day, 2 workers: {f['day_s']:8.1f} s median of {f['repeats']} ({_runs(f['day_s_runs'])}); speed-up "
        f"{f['speedup']:.2f}×, target ≤ {f['target_day_s']:.0f} s; tables identical: {f['identical_1_vs_2_workers']}"
    )
    if f["year_s"] is not None:
        print(f"  year 15 min, 2 workers: {f['year_s']:8.1f} s  (target ≤ {f['target_year_s']:.0f} s)")
