"""`opfbench run`'s study as a task family of the study engine (`study.engine`): check
everything, plan the tasks, run them (in process or on Dask), assemble steps.parquet, the
detail tables and summary.csv. A run with learned configurations fits them first
(`study.training`: the study's own nested runs over the training period)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import pandas as pd
import pyarrow as pa

from opfbench.io import load_case
from opfbench.jsonio import write_atomic
from opfbench.learned.fitted import LEARNED_DIR, TRAIN_DIR, Fitted
from opfbench.parquetio import ParquetStream
from opfbench.registry.catalog import configuration
from opfbench.schema import FRONTIER, KEYS, TASK_FRONTIER_SUMMARY, TASK_SUMMARY
from opfbench.study.config import LABEL_FIELDS, StudyConfig
from opfbench.study.engine import SILENT, EngineRun, Reporter, TaskOutput, run_family
from opfbench.study.periods import Period
from opfbench.study.run_tables import DETAIL_COLUMNS, extra_columns, step_columns, summarize, summarize_frontier
from opfbench.study.task_scenarios import check_model_forecasts, chunk_scenario, study_period
from opfbench.study.tasks import RunTask, TaskInput, plan_tasks, task_input

RUN_OUTPUTS = (
    "steps.parquet",
    "summary.csv",
    "frontier.parquet",
    "frontier.csv",
    "der_q.parquet",
    "bus_v.parquet",
    "report.html",
)


@dataclass
class StudyRun:
    """A finished run: its folder, summary, tasks run now and kept from before, wall time
    (s), each task's wall time, and the notes it made (`study.engine.Reporter`)."""

    out: Path
    config: StudyConfig
    period: Period
    tasks: list[RunTask]
    kept: int = 0
    ran: int = 0
    wall_s: float = 0.0
    summary: pd.DataFrame | None = None
    task_wall: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _bus_id(bus: object) -> int | str:
    """A bus's id as the manifest records it: a number, or a three-phase feeder's bus name."""
    return bus if isinstance(bus, str) else int(bus)  # type: ignore[call-overload]


def _case_info(case: str) -> dict:
    loaded = load_case(case)
    net = loaded.network
    return {
        "buses": int(net.n_bus),
        "ders": [
            {"name": name, "bus": _bus_id(net.bus_ids[d.bus]), "kind": d.kind, "rating_mw": float(d.rating_mw)}
            for name, d in zip(net.der_names, net.ders, strict=True)
        ],
        "vmin_pu": float(net.vmin.min()),
        "vmax_pu": float(net.vmax.max()),
        "loads": int(net.n_load),
        "series": None if loaded.series is None else loaded.series.source,
        "notes": list(loaded.notes),
        "data_sha256": loaded.data_sha256,
    }


@dataclass
class RunFamily:
    """The run's tasks (see `study.tasks`); the assembler streams steps.parquet, the
    frontier's steps and the detail tables and writes summary.csv and frontier.csv from
    the tasks' partial sums."""

    config: StudyConfig
    period: Period
    tasks: list[RunTask]
    kind: str = "run"
    outputs: tuple[str, ...] = RUN_OUTPUTS
    side_entries: tuple[str, ...] = (TRAIN_DIR, LEARNED_DIR)
    label_fields: tuple[str, ...] = LABEL_FIELDS

    @property
    def tables(self) -> tuple[str, ...]:
        return ("steps", "summary", "frontier", "frontier_summary", *self.config.detail_tables)

    def columns(self, table: str) -> list[str]:
        fixed = {
            "summary": TASK_SUMMARY.names,
            "frontier": FRONTIER.names,
            "frontier_summary": TASK_FRONTIER_SUMMARY.names,
        }
        if table == "steps":
            return step_columns(extra_columns(self.config.strategies))
        return fixed[table] if table in fixed else DETAIL_COLUMNS[table]

    @property
    def notes(self) -> tuple[str, ...]:
        return self.config.notes

    def manifest(self) -> dict:
        cases = {case: _case_info(case) for case in self.config.cases}
        return {
            "config": self.config.as_dict(),
            "config_digest": self.config.digest(),
            "data_sha256": {f"case {case}": info["data_sha256"] for case, info in cases.items()},
            "period": self.period.as_dict(),
            "data_sources": list(self.period.sources),
            "cases": cases,
            "strategies": {label: configuration(label).spec.record() for label in self.config.strategies},
        }

    def job(self, task: RunTask) -> TaskInput:
        return task_input(task, self.config, self.period)

    def runner(self) -> Callable[[TaskInput], TaskOutput]:
        from opfbench.study import tasks  # looked up at run time (tests replace it)

        return tasks.run_task

    def assembler(self, out: Path) -> "RunAssembler":
        return RunAssembler(out, self.config.detail_tables)

    def timings(self, wall_s: float) -> dict:
        return {}


class RunAssembler:
    """steps.parquet, frontier.parquet (+ the detail tables) streamed task by task in
    planned order as arrow tables (never pandas), summary.csv and frontier.csv from the
    partial sums on commit; all atomic."""

    def __init__(self, out: Path, detail: tuple[str, ...]):
        self.out = out
        self.writers = {name: ParquetStream(out / f"{name}.parquet") for name in ("steps", "frontier", *detail)}
        self.partials: list[pd.DataFrame] = []
        self.frontier: list[pd.DataFrame] = []
        self.order: list[tuple] = []

    def add(self, task: RunTask, tables: dict[str, pa.Table]) -> None:
        for name, writer in self.writers.items():
            writer.write(tables[name])
        partial = tables["summary"].to_pandas()
        self.partials.append(partial)
        self.frontier.append(tables["frontier_summary"].to_pandas())
        self.order.extend(map(tuple, partial[KEYS].itertuples(index=False)))

    def commit(self) -> pd.DataFrame:
        for w in self.writers.values():
            w.commit()
        summary = summarize(self.partials, list(dict.fromkeys(self.order)))
        # figures to 6 significant digits; k exactly (0.1 and 0.1000001 are two configurations)
        exact_k = summary.assign(k=summary["k"].map(_exact))
        write_atomic(self.out / "summary.csv", exact_k.to_csv(index=False, float_format="%.6g"))
        front = summarize_frontier(self.frontier)
        write_atomic(self.out / "frontier.csv", front.assign(k=front["k"].map(_exact)).to_csv(index=False, float_format="%.6g"))
        return summary

    def abort(self) -> None:
        for w in self.writers.values():
            w.abort()


def _exact(value: float) -> str:
    """`value` as 6 significant digits where that is exact, else its shortest exact text."""
    short = f"{value:.6g}"
    return short if float(short) == value else repr(value)


def prepare(config: StudyConfig) -> RunFamily:
    """Resolve the period, load the cases, plan the tasks — everything that can refuse the
    input, before any work."""
    period, cases = study_period(config.cases, config.forecast, config.period, config.night, config.step_minutes)
    config = replace(config.with_period(period.step_h * 60, period.step_h * len(period.index)), notes=config.notes + cases.notes)
    models = [s for s in config.forecast if s not in ("off", "oracle") and config.strategies_for(s)]
    check_model_forecasts(config.forecast_dir, models, period)  # a missing or incomplete forecast file: here, not in a worker
    running = {label for source in config.forecast for label in config.strategies_for(source)}
    extra_columns(config.strategies)  # a plugin's column that is one of the table's own: refused here
    data, sizes = {}, {}
    for case in config.cases:
        loaded = load_case(case)
        data[case] = loaded.data_sha256
        net = loaded.network
        sizes[case] = net.n_bus + len(net.ders)
        for label in config.strategies:
            if label in running:
                configuration(label).spec.check_network(net)
    tasks = plan_tasks(config, period, data, sizes)
    _probe_plugins(tasks, config, period)
    return RunFamily(config, period, tasks)


def _probe_plugins(tasks: list[RunTask], config: StudyConfig, period: Period) -> None:
    """Every plugin configuration run on the first steps of each case's first task that
    has it under each forecast (`plugins.probe_case`: the real DER kinds, shapes and
    read-only arrays), each night mode: InputError before anything is written."""
    from opfbench.plugins import probe_case

    probed: set[tuple[str, str, str]] = set()
    for task in tasks:
        for forecast, strategies in task.runs:
            key = (task.case, forecast)
            labels = [s for s in strategies if configuration(s).spec.source != "opfbench" and (*key, s) not in probed]
            if not labels:
                continue
            probed.update((*key, s) for s in labels)
            inp = task_input(task, config, period)
            step = pd.Timedelta(hours=inp.step_h)
            for mode in task.night_modes:
                scenario = chunk_scenario(
                    task.case, mode, forecast, inp.profiles, inp.night, min(2, inp.n_steps), step, inp.forecast_dir
                )
                probe_case(
                    labels,
                    scenario,
                    task.k,
                    f"{task.case}'s first steps (night mode {mode}, forecast {forecast})",
                    dict(inp.settings),
                )


def run_study(
    config: StudyConfig,
    out: Path,
    *,
    workers: int | None = 1,
    scheduler: str | None = None,
    fresh: bool = False,
    command: list[str] | None = None,
    fitted: tuple[Fitted, ...] | None = None,
    reporter: Reporter = SILENT,
) -> StudyRun:
    """Run `config` into the folder `out` (resuming finished tasks; `run_family` for the
    rest). Ctrl-C: `Stopped` after the finished tasks are saved. Its learned
    configurations are fitted first (`fit_learned`), unless `fitted` gives their rules
    (a nested training run's, whose case notes are its parent's to say)."""
    options: dict[str, Any] = {
        "workers": workers,
        "scheduler": scheduler,
        "fresh": fresh,
        "command": command,
        "reporter": reporter,
    }
    nested = fitted is not None
    if fitted is None:
        fitted = fit_learned(config, out, options)
    config = replace(config, fitted=fitted)
    run: EngineRun = run_family(lambda: prepare(config), out, **options, notes=not nested)
    family: RunFamily = run.family
    return StudyRun(
        run.out, family.config, family.period, family.tasks, run.kept, run.ran, run.wall_s, run.result, run.task_wall, run.notes
    )


def fit_learned(config: StudyConfig, out: Path, options: dict[str, Any]) -> tuple[Fitted, ...]:
    """The fitted rules of `config`'s learned configurations, after every check of the run
    itself (its input, the training periods apart from the test period, a params file's
    case, the folder's earlier run) — before any work: the `train=` ones fitted in nested
    runs of the folder `out` (`study.training`)."""
    from opfbench.study.store import RunStore
    from opfbench.study.training import recorded_fits, train
    from opfbench.study.training_checks import check_learned, learned_configs

    if not learned_configs(config.strategies):
        return ()
    family = prepare(config)
    c = family.config
    check_learned(c.strategies, c.cases, family.period, c.night, c.step_minutes)
    RunStore(Path(out), lambda msg: None).check(family, bool(options["fresh"]))

    def nested(sub: StudyConfig, folder: Path, rules: tuple[Fitted, ...]) -> StudyRun:
        return run_study(sub, folder, fitted=rules, **options)

    return train(family.config, Path(out), nested, {} if options["fresh"] else recorded_fits(Path(out)))
