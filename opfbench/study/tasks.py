"""Tasks: the grid split into independent pieces of work.

A task is (case, k, chunk of steps) and runs every requested strategy, night mode and
forecast source of that group, and the frontier of losses against voltage compliance of
each night mode (`formulations.frontier`, on the forecast-off scenario: the OPF reads no
forecast), which every configuration's steps are compared with — computed once, the
forecast-off `acopf` rows its point at ε = 0; at the steps where a configuration that may
curtail (Volt-Watt, reactive priority, `acopf:curtail=true`) did, also the frontier of the
optimum that may curtail, which it is compared with there. `acopf`, `acopf-paper` and `socp` share SOCP solves, and the
night modes — which differ only in the night hours, so their daytime snapshots are the
same problems — solve each once: the formulations' solve cache is keyed on the data
(`formulations.solves`), whatever Scenario objects carry it; a snapshot-wise strategy
(`StrategySpec.snapshot_wise`: every local rule, the SOCP) runs once on the distinct
snapshots of the night modes (`task_scenarios.SharedSnapshots`: by day, and at night where
the PV units produce nothing, the modes' snapshots are the same) and each mode takes its
rows, charged the wall time of the snapshots it brought; and where two night modes give
the very same scenario (no PV output in the night hours of the chunk), the second takes the
first's results (`Scenario.same_data`) with its wall time 0. Its input
carries its slice of the period's profiles, so it runs the same in this process, in a
local worker process or on a remote Dask worker; the AC OPF starts cold at each chunk and
warm-starts inside it — the same whatever the number of workers.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from opfbench.errors import InputError
from opfbench.formulations.frontier import (
    CAPABILITY,
    CAPABILITY_MVAR,
    FORECAST,
    RESERVE,
    Frontier,
    Part,
    capability,
    frontier,
    reference,
    within,
)
from opfbench.learned.fitted import Fitted
from opfbench.learned.rules import install
from opfbench.network import V_LIMIT_MAX_PU
from opfbench.plugins import PluginSource, ensure, loaded
from opfbench.registry.catalog import configuration, run_strategy
from opfbench.registry.options import OptionValue
from opfbench.registry.references import REFERENCE_OPTIMUM
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from opfbench.strategies.limits import reactive_limit
from opfbench.study.config import StudyConfig
from opfbench.study.engine import Task, TaskOutput
from opfbench.study.periods import Period
from opfbench.study.run_tables import (
    DETAIL_COLUMNS,
    FRONTIER_COLUMNS,
    Columns,
    detail_rows,
    extra_columns,
    frontier_rows,
    partial_frontier,
    partial_summary,
    stack,
    step_columns,
    step_rows,
)
from opfbench.study.task_scenarios import SharedSnapshots, chunk_scenario


@dataclass(frozen=True)
class RunTask(Task):
    """One piece of work of a run; `runs` the strategies (configuration labels) of each
    forecast source it runs; `start`/`end` are the first and last step (ISO, local time);
    `data_sha256` the case data's hash, `config_digest` the run's (both in its definition,
    so a checkpoint of other data or another config never matches); `fitted` (label,
    sha256) of the learned rules fitted for its case (in its definition when there are
    some: a checkpoint of another fit never matches)."""

    label: str
    case: str
    night_modes: tuple[str, ...]
    runs: tuple[tuple[str, tuple[str, ...]], ...]
    k: float
    start: str
    end: str
    data_sha256: str
    config_digest: str
    fitted: tuple[tuple[str, str], ...] = ()
    cost: float = field(default=1.0, compare=False)  # steps × (buses + DERs): no part of its definition

    @property
    def forecasts(self) -> tuple[str, ...]:
        return tuple(source for source, _ in self.runs)

    @property
    def affinity(self) -> str:
        """The case and chunk: its tasks (one per k) run back to back in one process, where
        they share the formulations' solves of the same data (e.g. at night, where a DER
        without Q at night has the limit 0 whatever k) through the solve cache."""
        return f"{self.case}|{self.start}|{self.end}"

    def definition(self) -> dict:
        fitted = {"fitted": dict(self.fitted)} if self.fitted else {}
        return fitted | {
            "case": self.case,
            "data_sha256": self.data_sha256,
            "night_modes": list(self.night_modes),
            "forecasts": {source: list(names) for source, names in self.runs},
            "k": self.k,
            "start": self.start,
            "end": self.end,
            "config_digest": self.config_digest,
        }

    def as_dict(self) -> dict:
        fields = {"case": self.case, "night_modes": list(self.night_modes), "k": self.k}
        runs = {"forecasts": {source: list(names) for source, names in self.runs}}
        return super().as_dict() | fields | runs | {"start": self.start, "end": self.end}


@dataclass(frozen=True)
class TaskInput:
    """Everything a worker needs: the task, its profiles (the chunk plus, when the
    period goes on, the next step), the night mask on those rows, the step, the run-level
    settings of the strategies' options (`StudyConfig.settings`), the extra step columns
    of the run's strategies, the plugins they come from (loaded in the worker first) and
    the fitted rules of the task's case (installed in the worker first)."""

    task: RunTask
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
    frontier: bool = True  # StudyConfig.frontier


def plan_tasks(config: StudyConfig, period: Period, data_sha256: dict[str, str], sizes: dict[str, int]) -> list[RunTask]:
    """Every task of the grid, in a fixed order (case, k, chunk), each running every
    forecast source with a strategy to run (only formulations asked: none under a
    forecast). `data_sha256`: each case's data hash; `sizes`: each case's buses + DERs
    (a task's cost is its steps × its case's size)."""
    tasks = []
    chunks = period.chunks(config.chunk)
    digest = config.digest()
    runs = tuple((source, names) for source in config.forecast if (names := config.strategies_for(source)))
    for case in config.cases:
        for k in config.ks:
            for rows in chunks:
                t0, t1 = period.index[rows.start], period.index[rows.stop - 1]
                label = f"{case}_k{k:g}_{t0:%Y%m%dT%H%M}"
                tasks.append(
                    RunTask(
                        label,
                        case,
                        config.night_modes,
                        runs,
                        float(k),
                        t0.isoformat(),
                        t1.isoformat(),
                        data_sha256[case],
                        digest,
                        tuple((f.label, f.sha256) for f in config.fitted if f.case == case),
                        float((rows.stop - rows.start) * sizes[case]),
                    )
                )
    return tasks


def task_input(task: RunTask, config: StudyConfig, period: Period) -> TaskInput:
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
        config.frontier,
    )


def fitted_options(fitted: tuple[Fitted, ...]) -> dict[str, dict[str, OptionValue]]:
    """Install the fitted rules (under their references) and return, per label fitted by
    the run (`train=`), the options that make it run with them."""
    install({f.ref: f.parsed() for f in fitted})
    configs = {f.label: configuration(f.label) for f in fitted}
    return {f.label: configs[f.label].spec.fitted_options(f.ref) for f in fitted if configs[f.label].options()["train"]}


def curtails(label: str) -> bool:
    """Whether a configuration's DER may deliver less active power than they have: where
    it curtails it is compared with the frontier of the optimum that may curtail
    (`Configuration.curtails`)."""
    return configuration(label).curtails


def _curtailed(res: StrategyResult) -> np.ndarray:
    """(S,) the steps where `res` curtailed some power."""
    return np.nan_to_num(res.curtailed_kw) > 0


PartKey = tuple[bool, str, str]  # a partial frontier: (curtail, limit, the forecast source of a FORECAST limit)


def _needs(
    scenarios: dict[tuple[str, str], Scenario], mode: str, configs: list[tuple[str, str, StrategyResult]], k: float
) -> tuple[dict[PartKey, dict[tuple[str, str], np.ndarray]], dict[tuple[str, str], np.ndarray]]:
    """Per partial frontier each configuration's (source, name) steps (S,) bool whose
    reference it is (`formulations.frontier`, the tightest set that holds the step): where
    it curtailed, the optimum that may curtail at k, or at k = 0 where it used its reserve;
    where it used its reserve only, the optimum at its forecast source's Algorithm 3 limit
    (`strategies.limits.reactive_limit`, capped at the capability), else at k = 0; and each
    configuration's steps whose setpoints exceed the capability, or whose |V| lies beyond the
    physical limits of the widest frontier point (`network.V_LIMIT_MAX_PU`): no frontier
    bounds them."""
    out: dict[PartKey, dict[tuple[str, str], np.ndarray]] = {}
    unbounded: dict[tuple[str, str], np.ndarray] = {}
    for source, name, res in configs:
        scenario = scenarios[mode, source]
        cap = capability(scenario, res)
        kept, fits = within(res, (1.0 - k) * cap), within(res, cap, CAPABILITY_MVAR)
        cut = _curtailed(res) if curtails(name) else np.zeros(res.n_snapshots, dtype=bool)
        used = ~kept & fits
        masks = {(True, RESERVE, ""): cut & kept, (True, CAPABILITY, ""): cut & used}
        if scenario.der_p_forecast_mw is not None:
            forecast = ~cut & used & within(res, reactive_limit(scenario, k, safe=True))
            masks[False, FORECAST, source] = forecast
            used = used & ~forecast
        masks[False, CAPABILITY, ""] = ~cut & used
        for key, mask in masks.items():
            out.setdefault(key, {})[source, name] = mask
        with np.errstate(invalid="ignore"):  # a |V| beyond the physical limits the widest frontier point keeps
            wild = ((res.vm < 0.0) | (res.vm > V_LIMIT_MAX_PU)).any(axis=1)
        unbounded[source, name] = ~fits | wild
    return out, unbounded


def _part(
    plain: Scenario, scenarios: dict[tuple[str, str], Scenario], mode: str, key: PartKey, rows: np.ndarray, k: float
) -> Part:
    """The partial frontier `key` (`_needs`) on the steps `rows` of the task's `plain` scenario."""
    curtail, limit, source = key
    sub = plain.take(rows)
    if limit == FORECAST:  # the OPF's DER at Algorithm 3's limit (capped at the capability) of that forecast source
        q_limit = reactive_limit(scenarios[mode, source], k, safe=True)[rows]
        return Part(frontier(replace(sub, q_limit_mvar=q_limit), k, limit=FORECAST), rows)
    return Part(frontier(sub, k if limit == RESERVE else 0.0, curtail=curtail, limit=limit), rows)


def run_task(inp: TaskInput) -> TaskOutput:
    """Run every night mode, forecast source and strategy of the task, the strategies of a
    (night mode, source) on one scenario — a snapshot-wise strategy once on the night modes'
    distinct snapshots of the source —, and each night mode's frontier (module docstring;
    single-threaded BLAS, so results are bit-identical wherever it runs)."""
    from opfbench.io import load_case
    from opfbench.timing import elapsed_ms, now

    start = now()
    t = inp.task
    if load_case(t.case).data_sha256 != t.data_sha256:
        raise InputError(f"case {t.case}: its data changed while the run went on (or differ on this worker); rerun")
    ensure(inp.plugins)
    overrides = fitted_options(inp.fitted)
    settings = dict(inp.settings)
    with threadpool_limits(1):
        step = pd.Timedelta(hours=inp.step_h)
        time, night = inp.profiles.index[: inp.n_steps], inp.night[: inp.n_steps]
        steps: list[Columns] = []
        fronts: list[Columns] = []
        detail: dict[str, list[Columns]] = {name: [] for name in inp.detail}
        ran: list[tuple[Scenario, dict[str, StrategyResult]]] = []
        drawn: list[tuple[Scenario, Frontier]] = []

        def scenario_of(mode: str, source: str) -> Scenario:
            return chunk_scenario(t.case, mode, source, inp.profiles, inp.night, inp.n_steps, step, inp.forecast_dir)

        scenarios = {(mode, source): scenario_of(mode, source) for mode in t.night_modes for source, _ in t.runs}
        shared = {
            source: SharedSnapshots.of([scenarios[mode, source] for mode in t.night_modes])
            for source, _ in t.runs
            if len(t.night_modes) > 1
        }
        union: dict[tuple[str, str], StrategyResult] = {}  # snapshot-wise strategies, run once per source

        def result(j: int, source: str, name: str) -> StrategyResult:
            """`name` on night mode j under `source`: its rows of the night modes' union run, or its own run."""
            share = shared.get(source)
            if share is not None and configuration(name).spec.snapshot_wise:
                if (source, name) not in union:
                    union[source, name] = run_strategy(name, share.union, t.k, settings, **overrides.get(name, {}))
                whole = union[source, name]
                return whole.take(share.rows[j], whole.wall_ms * share.share(j))
            return run_strategy(name, scenarios[t.night_modes[j], source], t.k, settings, **overrides.get(name, {}))

        for j, mode in enumerate(t.night_modes):
            by_source: dict[str, dict[str, StrategyResult]] = {}
            for source, names in t.runs:
                scenario = scenarios[mode, source]
                same = next((results for earlier, results in ran if earlier.same_data(scenario)), None)
                results = by_source[source] = {}
                for name in names:
                    results[name] = replace(same[name], wall_ms=0.0) if same is not None else result(j, source, name)
                if same is None:
                    ran.append((scenario, results))
            plain = scenario_of(mode, "off")
            front = next((f for earlier, f in drawn if earlier.same_data(plain)), None)
            if front is None and inp.frontier:
                front = frontier(plain, t.k, at_zero=by_source.get("off", {}).get(REFERENCE_OPTIMUM))
                drawn.append((plain, front))
            if front is not None:
                fronts.append(frontier_rows(t.case, t.k, mode, time, inp.step_h, front))
            configs = [(source, name, res) for source, results in by_source.items() for name, res in results.items()]
            needs, unbounded = ({}, {}) if front is None else _needs(scenarios, mode, configs, t.k)
            parts: dict[PartKey, Part] = {}
            for key, masks in needs.items():
                rows = np.flatnonzero(np.logical_or.reduce([*masks.values(), np.zeros(inp.n_steps, dtype=bool)]))
                if rows.size:
                    part = parts[key] = _part(plain, scenarios, mode, key, rows, t.k)
                    if key[1] == RESERVE:  # the optimum that may curtail at k: a frontier of the run (the others are partial)
                        fronts.append(frontier_rows(t.case, t.k, mode, time[rows], inp.step_h, part.front))
            for source, name, res in configs:
                ref = None
                if front is not None:
                    which = [(part, needs[kind][source, name]) for kind, part in parts.items() if (source, name) in needs[kind]]
                    ref = reference(front, res.voltage_violation(), which, unbounded[source, name])
                steps.append(step_rows(t.case, mode, source, time, inp.step_h, night, res, inp.columns, ref))
                for table, columns in detail_rows(t.case, mode, source, time, res, inp.detail).items():
                    detail[table].append(columns)
        table = stack(steps, step_columns(inp.columns), time.tz)
        front_table = stack(fronts, FRONTIER_COLUMNS, time.tz)
    details = {name: stack(parts, DETAIL_COLUMNS[name], time.tz) for name, parts in detail.items()}
    tables = {"steps": table, "summary": partial_summary(table), "frontier": front_table}
    tables["frontier_summary"] = partial_frontier(front_table)
    return TaskOutput(t, tables | details, elapsed_ms(start) / 1e3)
