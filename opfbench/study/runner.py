"""A study from config to run folder: check everything, plan the tasks, skip the finished
ones, run the rest (in process or on Dask), assemble the tables."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from opfbench.io import load_network
from opfbench.registry import configuration
from opfbench.study.config import StudyConfig
from opfbench.study.execution import STOPPED, execute
from opfbench.study.fitted import Fitted
from opfbench.study.learning import check_learned
from opfbench.study.periods import Period
from opfbench.study.progress import Progress
from opfbench.study.scenarios import study_period
from opfbench.study.store import RunStore
from opfbench.study.tasks import Task, TaskOutput, plan_tasks, task_input
from opfbench.study.training import train
from opfbench.timing import elapsed_ms, now


@dataclass
class StudyRun:
    """A finished (or interrupted) run: its folder, summary (None if interrupted), tasks
    run now and kept from before, wall time (s)."""

    out: Path
    config: StudyConfig
    period: Period
    tasks: list[Task]
    kept: int = 0
    ran: int = 0
    wall_s: float = 0.0
    summary: pd.DataFrame | None = None
    task_wall: dict = field(default_factory=dict)


def prepare(config: StudyConfig) -> tuple[StudyConfig, Period, list[Task]]:
    """Resolve the period, load the cases, plan the tasks — everything that can refuse the
    input, before any work."""
    period, cases = study_period(config.cases, config.forecast, config.period, config.night, config.step_minutes)
    config = replace(config.with_period(period.step_h * 60, period.step_h * len(period.index)), notes=config.notes + cases.notes)
    models = [s for s in config.forecast if s not in ("off", "oracle") and config.strategies_for(s)]
    if models:  # a missing or incomplete forecast file is refused here, not in a worker
        from opfbench.forecasting.outputs import load_forecast

        for model in models:
            load_forecast(config.forecast_dir, "pv", model)
    running = {label for source in config.forecast for label in config.strategies_for(source)}
    for case in config.cases:
        net = load_network(case)
        for label in config.strategies:
            if label in running:
                configuration(label).spec.check_network(net)
    return config, period, plan_tasks(config, period)


def run_study(
    config: StudyConfig,
    out: Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    fresh: bool = False,
    quiet: bool = False,
    command: list[str] | None = None,
    fitted: tuple[Fitted, ...] | None = None,
) -> StudyRun:
    """Run `config` into the folder `out` (resuming finished tasks). KeyboardInterrupt
    propagates after the finished tasks are saved; `StudyRun.kept` counts them then.
    Learned configurations are trained first (`study.training`, nested run folders in
    `out`) unless `fitted` gives their fitted rules (a nested run's)."""
    say = (lambda msg: None) if quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    start = now()
    store = RunStore(out, say)
    config, period, tasks = prepare(config)
    if fitted is None:
        check_learned(config.strategies, config.cases, period)

        def nested(sub: StudyConfig, folder: Path, rules: tuple[Fitted, ...]) -> StudyRun:
            return run_study(
                sub, folder, workers=workers, scheduler=scheduler, fresh=fresh, quiet=quiet, command=command, fitted=rules
            )

        fitted = train(config, store.out, nested)
    config = replace(config, fitted=fitted)
    for note in config.notes:
        say(note)
    run = StudyRun(store.out, config, period, tasks)
    with store:
        done = store.open(config, period, tasks, command or [], fresh)
        pending = [task_input(t, config, period) for t in tasks if t.id not in done]
        progress = Progress(len(tasks), len(done), quiet)
        run.kept = len(done)
        assembly = store.assembly(tasks, config.detail_tables)

        def save(result: TaskOutput) -> None:
            store.save(result)
            run.kept += 1
            run.ran += 1
            run.task_wall[result.task.id] = result.wall_s
            progress.update(result)
            assembly.advance()

        def stop() -> None:  # Ctrl-C in the in-process path: every finished task is on disk
            progress.close()
            assembly.abort()
            store.lock.unlink(missing_ok=True)
            print(
                f"\nstopped; {run.kept} tasks kept in {store.out}; rerun the same command to resume", file=sys.stderr, flush=True
            )
            os._exit(STOPPED)

        try:
            assembly.advance()  # the tasks kept from before
            try:
                workers_exited = execute(pending, save, workers, scheduler, stop)
            finally:  # also after an interrupt: the manifest marks the finished tasks
                progress.close()
                store.finish_manifest(None, workers, scheduler, run.task_wall)
            run.summary = assembly.finish()
        finally:
            assembly.abort()
        workers_exited()  # before the manifest records the worker processes' peak memory
        run.wall_s = elapsed_ms(start) / 1e3
        store.finish_manifest(run.wall_s, workers, scheduler, run.task_wall)
    return run
