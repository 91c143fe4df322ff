"""Tasks: the grid split into independent pieces of work.

A task is (case, forecast, k, chunk of steps) and runs every requested strategy and
night mode of that group. `acopf`, `acopf-paper` and `socp` share SOCP solves, and the
night modes — which differ only in the night hours, so their daytime snapshots are the
same problems — solve each once: the formulations' solve cache is keyed on the data
(`formulations.relaxation`), whatever Scenario objects carry it; and where two
night modes give the very same scenario (no PV output in the night hours of the chunk), the
second takes the first's results (`Scenario.same_data`) with its wall time 0. Its input
carries its slice of the period's profiles, so it runs the same in this process, in a
local worker process or on a remote Dask worker; the AC OPF starts cold at each chunk and
warm-starts inside it — the same whatever the number of workers.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from opfbench.plugins import PluginSource, ensure, loaded
from opfbench.registry import OptionValue, configuration, run_strategy
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from opfbench.strategies.learned import install
from opfbench.study.config import StudyConfig
from opfbench.study.fitted import Fitted
from opfbench.study.periods import Period
from opfbench.study.scenarios import chunk_scenario
from opfbench.study.tables import (
    DETAIL_COLUMNS,
    Columns,
    detail_rows,
    extra_columns,
    partial_summary,
    stack,
    step_columns,
    step_rows,
)


@dataclass(frozen=True)
class Task:
    """One piece of work; `start`/`end` are the first and last step (ISO, local time)."""

    id: str
    case: str
    night_modes: tuple[str, ...]
    forecast: str
    k: float
    strategies: tuple[str, ...]
    start: str
    end: str

    @property
    def file(self) -> str:
        return f"tasks/{self.id}.parquet"

    def as_dict(self) -> dict:
        return asdict(self) | {"night_modes": list(self.night_modes), "strategies": list(self.strategies), "file": self.file}


@dataclass(frozen=True)
class TaskInput:
    """Everything a worker needs: the task, its profiles (the chunk plus, when the
    period goes on, the next step), the night mask on those rows, the step, the run-level
    settings of the strategies' options (`StudyConfig.settings`), the extra step columns
    of the run's strategies, the plugins they come from (loaded in the worker first) and
    the fitted rules of the task's case (installed in the worker first)."""

    task: Task
    profiles: pd.DataFrame
    night: np.ndarray
    n_steps: int
    step_h: float
    forecast_dir: str
    detail: tuple[str, ...]  # the long tables to write (`tables.DETAIL_TABLES`)
    settings: tuple[tuple[str, str], ...] = ()
    columns: tuple[str, ...] = ()
    plugins: tuple[PluginSource, ...] = ()
    fitted: tuple[Fitted, ...] = ()


@dataclass
class TaskOutput:
    """A finished task's tables (`summary`: its partial sums, `tables.partial_summary`;
    `detail`: the requested long tables by name) and wall time (s)."""

    task: Task
    steps: pd.DataFrame
    summary: pd.DataFrame
    detail: dict[str, pd.DataFrame]
    wall_s: float


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-")


def plan_tasks(config: StudyConfig, period: Period) -> list[Task]:
    """Every task of the grid, in a fixed order (case, forecast, k, chunk). A forecast
    source with no strategy to run (only formulations asked) adds none."""
    tasks = []
    chunks = period.chunks(config.chunk)
    for case in config.cases:
        for source in config.forecast:
            names = config.strategies_for(source)
            if not names:
                continue
            for k in config.ks:
                for rows in chunks:
                    t0, t1 = period.index[rows.start], period.index[rows.stop - 1]
                    ident = f"{_slug(case)}_{_slug(source)}_k{k:g}_{t0:%Y%m%dT%H%M}"
                    tasks.append(Task(ident, case, config.night_modes, source, float(k), names, t0.isoformat(), t1.isoformat()))
    return tasks


def task_input(task: Task, config: StudyConfig, period: Period) -> TaskInput:
    """The task's input: its rows of the period, plus the next step when there is one."""
    index = period.index
    first = index.get_loc(pd.Timestamp(task.start))
    last = index.get_loc(pd.Timestamp(task.end))
    stop = min(last + 2, len(index))
    return TaskInput(
        task,
        period.profiles.iloc[first:stop][["load", "pv", "wind"]],
        period.night[first:stop],
        last + 1 - first,
        period.step_h,
        config.forecast_dir,
        config.detail_tables,
        tuple(config.settings().items()),
        extra_columns(config.strategies),
        loaded(config.plugins),
        tuple(f for f in config.fitted if f.case == task.case),
    )


def fitted_options(fitted: tuple[Fitted, ...]) -> dict[str, dict[str, OptionValue]]:
    """Install the fitted rules (under their references) and return, per label fitted by
    the run (`train=`), the options that make it run with them."""
    install({f.ref: f.parsed() for f in fitted})
    configs = {f.label: configuration(f.label) for f in fitted}
    return {f.label: configs[f.label].spec.fitted_options(f.ref) for f in fitted if configs[f.label].options()["train"]}


def run_task(inp: TaskInput) -> TaskOutput:
    """Run every night mode and strategy of the task, the strategies of a night mode on one
    scenario (single-threaded BLAS, so results are bit-identical wherever it runs)."""
    from opfbench.timing import elapsed_ms, now

    start = now()
    t = inp.task
    ensure(inp.plugins)
    overrides = fitted_options(inp.fitted)
    settings = dict(inp.settings)
    with threadpool_limits(1):
        step = pd.Timedelta(hours=inp.step_h)
        time, night = inp.profiles.index[: inp.n_steps], inp.night[: inp.n_steps]
        steps: list[Columns] = []
        detail: dict[str, list[Columns]] = {name: [] for name in inp.detail}
        ran: list[tuple[Scenario, dict[str, StrategyResult]]] = []
        for mode in t.night_modes:
            scenario = chunk_scenario(t.case, mode, t.forecast, inp.profiles, inp.night, inp.n_steps, step, inp.forecast_dir)
            same = next((results for earlier, results in ran if earlier.same_data(scenario)), None)
            results = {}
            for name in t.strategies:
                res = results[name] = (
                    replace(same[name], wall_ms=0.0)
                    if same is not None
                    else run_strategy(name, scenario, t.k, settings, **overrides.get(name, {}))
                )
                steps.append(step_rows(t.case, mode, t.forecast, time, inp.step_h, night, res, inp.columns))
                for table, columns in detail_rows(t.case, mode, t.forecast, time, res, inp.detail).items():
                    detail[table].append(columns)
            if same is None:
                ran.append((scenario, results))
        table = stack(steps, step_columns(inp.columns), time.tz)
    return TaskOutput(
        t,
        table,
        partial_summary(table),
        {name: stack(parts, DETAIL_COLUMNS[name], time.tz) for name, parts in detail.items()},
        elapsed_ms(start) / 1e3,
    )
