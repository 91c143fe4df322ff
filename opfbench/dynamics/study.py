"""The fault ride-through study as a task family of the study engine (`study.engine`):
fault buses × strategies × k × forecast × model variants on one operating point, with
the engine's checkpoints, resume, lock, Dask and progress. Its folder (docs/CONTRACTS.md,
fault folder): `fault.parquet` (one row per simulation × bus), `traces.parquet` (|V| and
Q at the DER buses and the fault bus, 5-ms samples), `manifest.json`, `tasks/`.

Planning runs the strategies (opaque configuration labels, through the registry) on the
operating point for their pre-fault setpoints; identical setpoints of one model variant
(no action at every k, a strategy whose k does not bind) make one task — one dynamic
model, every fault bus simulated on it — whose rows are recorded for each configuration.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pyarrow as pa

from opfbench.capability import PAPER_KS, check_reserve
from opfbench.digests import digest
from opfbench.dynamics.params import DIVERGED, FORECASTS, NOT_RECOVERED, RECOVERED, RECOVERY_PU, FaultParams, ModelParams
from opfbench.dynamics.point import OperatingPoint, operating_point
from opfbench.dynamics.recovery import recovery_table
from opfbench.dynamics.rms_model import build_model, check_modelled, prefault_flow
from opfbench.dynamics.simulate import MARGIN_WINDOW_S, TRACE_EVERY_S, Simulation, check_fault, simulate
from opfbench.errors import InputError
from opfbench.io import Case
from opfbench.network import Network
from opfbench.parquetio import ParquetStream, arrow_table, write_parquet
from opfbench.registry.catalog import get_strategy, run_strategy
from opfbench.registry.references import DEFAULT_FAULT
from opfbench.scenario import Scenario
from opfbench.schema import FAULT, FAULT_TASK, FAULT_TASK_TRACES, TRACES
from opfbench.study.config import check_something_to_run, strategies_for, unique_grid
from opfbench.study.engine import SILENT, EngineRun, Reporter, Task, TaskOutput, run_family
from opfbench.threads import one_blas_thread
from opfbench.timing import elapsed_ms, now

FAULT_OUTPUTS = ("fault.parquet", "traces.parquet")
#: A task's tables: per bus of each fault, and the traces (`opfbench.schema`).
TASK_COLUMNS = {"measures": FAULT_TASK.names, "traces": FAULT_TASK_TRACES.names}


@dataclass(frozen=True)
class FaultConfig:
    """What to run. `fault_buses` external bus numbers; `strategies` configuration labels
    the registry runs; `variants` labels understood by `ModelParams.with_variant`, applied
    on top of `params`; `fault` the template (its bus is replaced by each fault bus);
    `load_scale`, `der_scale`, `time` choose the operating point (`operating_point`)."""

    case: str
    fault_buses: tuple[int, ...]
    strategies: tuple[str, ...] = DEFAULT_FAULT
    ks: tuple[float, ...] = PAPER_KS
    forecasts: tuple[str, ...] = ("off",)
    variants: tuple[str, ...] = ("reference",)
    params: ModelParams = field(default_factory=ModelParams)
    fault: FaultParams = field(default_factory=lambda: FaultParams(bus=0))
    load_scale: float = 1.0
    der_scale: float = 0.8
    time: str | None = None
    notes: tuple[str, ...] = field(default=(), compare=False)

    @classmethod
    def build(cls, **fields) -> "FaultConfig":
        """A config with repeated grid values dropped; `notes` say what was dropped."""
        labels = {"fault_buses": "fault buses", "strategies": "strategies", "ks": "k values", "forecasts": "forecasts"}
        unique, notes = unique_grid(fields, labels | {"variants": "variants"})
        return cls(**unique, notes=notes)

    def check(self, net: Network) -> dict[str, ModelParams]:
        """Validate everything before any work starts; return the params of each variant."""
        check_modelled(net)
        known = set(int(b) for b in net.bus_ids)
        bad = [b for b in self.fault_buses if b not in known]
        if bad:
            raise InputError(f"{net.name}: no bus {bad[0]} to fault (buses {net.bus_ids.min()}..{net.bus_ids.max()})")
        for name in self.strategies:
            get_strategy(name)
        for k in self.ks:
            check_reserve(k)
        for fc in self.forecasts:
            if fc not in FORECASTS:
                raise InputError(f"unknown forecast {fc!r}; choose from {', '.join(FORECASTS)}")
        check_something_to_run(self.strategies, self.forecasts)
        self.params.check()
        variants = {label: self.params.with_variant(label) for label in self.variants}
        for params in variants.values():
            for b in self.fault_buses:
                check_fault(net, params, replace(self.fault, bus=b))
        return variants

    def as_dict(self) -> dict:
        """The manifest's `config` (JSON-ready)."""
        fault = asdict(self.fault)
        fault.pop("bus")
        return {
            "case": self.case,
            "fault_buses": list(self.fault_buses),
            "strategies": list(self.strategies),
            "ks": list(self.ks),
            "forecasts": list(self.forecasts),
            "variants": list(self.variants),
            "model": self.params.as_dict(),
            "fault": fault,
            "load_scale": self.load_scale,
            "der_scale": self.der_scale,
            "time": self.time,
        }

    def digest(self) -> str:
        return digest(self.as_dict())[:16]


@dataclass(frozen=True)
class FaultTask(Task):
    """One dynamic model — a model variant at one set of DER setpoints `q_mvar` (MVAr) on
    the operating point — with every fault bus simulated on it. `emf_pu` the source EMF
    it is built with (None: re-set to the slack's scheduled voltage)."""

    label: str
    case: str
    data_sha256: str
    point_sha256: str
    variant: str
    params: ModelParams
    emf_pu: float | None
    q_mvar: tuple[float, ...]
    fault: FaultParams
    fault_buses: tuple[int, ...]

    def definition(self) -> dict:
        fault = asdict(self.fault)
        fault.pop("bus")
        return {
            "case": self.case,
            "data_sha256": self.data_sha256,
            "operating_point_sha256": self.point_sha256,
            "variant": self.variant,
            "model": self.params.as_dict(),
            "emf_pu": self.emf_pu,
            "q_mvar": list(self.q_mvar),
            "fault": fault,
            "fault_buses": list(self.fault_buses),
        }


@dataclass(frozen=True)
class FaultJob:
    """A task's input: the task and the operating point without forecast."""

    task: FaultTask
    scenario: Scenario


@dataclass(frozen=True)
class Configuration:
    """One simulated configuration: a strategy at k under a forecast in a model variant,
    and the task (index) whose model it runs on."""

    variant: str
    params: ModelParams
    strategy: str
    k: float
    forecast: str
    task: int


def _setpoints(config: FaultConfig, point: OperatingPoint) -> dict[tuple[str, float, str], np.ndarray]:
    """Every configuration's pre-fault DER setpoints (MVAr), by (strategy, k, forecast);
    a strategy runs under a forecast only if the registry says it reads one."""
    out = {}
    for fc in config.forecasts:
        sc = point.scenario if fc == "oracle" else point.scenario.without_forecast()
        for name in strategies_for(config.strategies, fc):
            for k in config.ks:
                res = run_strategy(name, sc, k)
                if res.status[0] not in ("ok",) and not str(res.status[0]).startswith("fallback"):
                    raise InputError(f"strategy {name} at k = {k:g} gave status {res.status[0]} on this operating point")
                out[name, k, fc] = res.q_mvar[0]
    return out


@dataclass
class FaultFamily:
    """The fault study's tasks and configurations (see the module docstring)."""

    config: FaultConfig
    case: Case
    point: OperatingPoint
    variants: dict[str, ModelParams]
    tasks: list[FaultTask]
    configurations: list[Configuration]
    kind: str = "fault"
    tables: tuple[str, ...] = ("measures", "traces")
    outputs: tuple[str, ...] = FAULT_OUTPUTS
    side_entries: tuple[str, ...] = ()
    label_fields: tuple[str, ...] = ()

    @property
    def notes(self) -> tuple[str, ...]:
        return self.config.notes

    def manifest(self) -> dict:
        return {
            "case": self.config.case,
            "operating_point": self.point.label,
            "config": self.config.as_dict(),
            "config_digest": self.config.digest(),
            "data_sha256": {f"case {self.config.case}": self.case.data_sha256, "operating point": self.point.data_sha256},
            "model": self.config.params.as_dict(),
            "variants": {label: params.as_dict() for label, params in self.variants.items()},
            "fault": self.config.as_dict()["fault"],
            "integrator": {
                "method": "classical Runge–Kutta (RK4), fixed step",
                "step_s": self.config.fault.step_s,
                "network": "current injection, fixed point over the DER buses to 1e-12 p.u.",
            },
            "recovery": {"threshold_pu": RECOVERY_PU, "margin_window_s": MARGIN_WINDOW_S, "trace_step_s": TRACE_EVERY_S},
            "files": {
                "fault.parquet": "one row per (simulation, bus)",
                "traces.parquet": "|V| and Q at the DER buses and the fault bus, 5-ms samples",
            },
        }

    def columns(self, table: str) -> list[str]:
        return TASK_COLUMNS[table]

    def job(self, task: FaultTask) -> FaultJob:
        return FaultJob(task, self.point.scenario.without_forecast())

    def runner(self) -> Callable[[FaultJob], TaskOutput]:
        return simulate_task

    def assembler(self, out: Path) -> "FaultAssembler":
        return FaultAssembler(out, self)

    def timings(self, wall_s: float) -> dict:
        n = len(self.tasks)
        return {"study_s": wall_s, "simulations": n * len(self.config.fault_buses), "models": n}


def plan(config: FaultConfig, case: Case) -> FaultFamily:
    """Check the config, choose the operating point, run the strategies for their
    setpoints and make one task per distinct model of each variant."""
    net = case.balanced("the fault study (a balanced three-phase RMS model)")
    variants = config.check(net)
    point = operating_point(net, config.load_scale, config.der_scale, config.time, case)
    with one_blas_thread():
        setpoints = _setpoints(config, point)
    sc_off = point.scenario.without_forecast()
    tasks: list[FaultTask] = []
    configurations = []
    for label, params in variants.items():
        emf = params.source.emf_pu if params.source.emf == "given" else None
        if params.source.emf == "held":
            emf = float(abs(prefault_flow(sc_off, np.zeros(len(net.ders)), params)[1]))
        unique: dict[bytes, int] = {}
        for (name, k, fc), q in setpoints.items():
            key = np.round(q, 12).tobytes()
            if key not in unique:
                unique[key] = len(tasks)
                tasks.append(
                    FaultTask(
                        f"{label}_{name}_k{k:g}_{fc}",
                        config.case,
                        case.data_sha256,
                        point.data_sha256,
                        label,
                        params,
                        emf,
                        tuple(float(v) for v in q),
                        config.fault,
                        config.fault_buses,
                    )
                )
            configurations.append(Configuration(label, params, name, float(k), fc, unique[key]))
    return FaultFamily(config, case, point, variants, tasks, configurations)


def _trace(sim: Simulation) -> pd.DataFrame:
    """|V| and Q at the DER buses and the fault bus, 5-ms samples (long table)."""
    net = sim.model.net
    der = list(net.der_bus)
    buses = der + ([sim.fault_index] if sim.fault_index not in der else [])
    parts = []
    for b in buses:
        q = sim.q_trace_mvar[:, der.index(b)] if b in der else np.full(len(sim.t_trace), np.nan)
        parts.append(pd.DataFrame({"bus": int(net.bus_ids[b]), "t_s": sim.t_trace, "v_pu": sim.vm_trace[:, b], "q_mvar": q}))
    return pd.concat(parts, ignore_index=True)


def _measures(sim: Simulation, fault_bus: int) -> pd.DataFrame:
    """One row per bus: recovery, status, lowest |V|, margin (and the simulation's motors
    stalled and wall time)."""
    net = sim.model.net
    recovery = sim.recovery_ms()
    if sim.ok:
        status = np.where(np.isnan(recovery), NOT_RECOVERED, RECOVERED).astype(object)
    else:
        status = np.full(len(recovery), DIVERGED, dtype=object)
    ids = net.bus_ids.astype(np.int64)
    return pd.DataFrame(
        {
            "fault_bus": np.full(len(ids), fault_bus, dtype=np.int64),
            "bus": ids,
            "recovery_ms": recovery,
            "status": status,
            "vmin_pu": sim.vmin(),
            "margin_pu": sim.margin_pu(),
            "motors_stalled": np.full(len(ids), sim.motors_stalled(), dtype=np.int64),
            "sim_ms": np.full(len(ids), sim.sim_ms),
            "der_bus": np.isin(np.arange(len(ids)), net.der_bus),
            "faulted": ids == fault_bus,
        },
        columns=TASK_COLUMNS["measures"],
    )


def simulate_task(job: FaultJob) -> TaskOutput:
    """Build the task's model and simulate every fault bus on it (single-threaded BLAS,
    so results are bit-identical wherever it runs)."""
    start = now()
    t = job.task
    measures, traces = [], []
    with one_blas_thread():
        model = build_model(job.scenario, np.array(t.q_mvar), t.params, t.emf_pu)
        for bus in t.fault_buses:
            sim = simulate(model, replace(t.fault, bus=bus))
            measures.append(_measures(sim, bus))
            traces.append(_trace(sim).assign(fault_bus=bus)[TASK_COLUMNS["traces"]])
    tables = {"measures": pd.concat(measures, ignore_index=True), "traces": pd.concat(traces, ignore_index=True)}
    return TaskOutput(t, tables, elapsed_ms(start) / 1e3)


class FaultAssembler:
    """fault.parquet and traces.parquet, one configuration after another in planned order
    as their tasks arrive (a task's tables kept until its last configuration is written):
    the traces streamed as arrow tables in batches of TRACE_BATCH rows, the fault table
    written on commit (after the traces)."""

    def __init__(self, out: Path, family: FaultFamily):
        self.out, self.family = out, family
        self.traces = ParquetStream(out / "traces.parquet")
        self.batch: list[pa.Table] = []
        self.rows: list[pa.Table] = []
        self.tables: dict[int, dict[str, pa.Table]] = {}
        self.left = np.bincount([c.task for c in family.configurations], minlength=len(family.tasks))
        self.index = {t.id: i for i, t in enumerate(family.tasks)}
        self.next = 0

    def add(self, task: FaultTask, tables: dict[str, pa.Table]) -> None:
        self.tables[self.index[task.id]] = tables
        configurations = self.family.configurations
        while self.next < len(configurations) and configurations[self.next].task in self.tables:
            self._write(configurations[self.next])
            self.next += 1

    def _write(self, c: Configuration) -> None:
        tables = self.tables[c.task]
        src = c.params.source
        label: dict[str, str | float] = {"case": self.family.config.case, "strategy": c.strategy, "k": c.k}
        label |= {"forecast": c.forecast, "variant": c.variant}
        model: dict[str, str | float] = {"source_impedance_pu": src.impedance_pu, "emf": str(src.emf)}
        model["motor_share"] = c.params.motors.share
        self.rows.append(_labelled(tables["measures"], label | model, FAULT.names))
        self.batch.append(_labelled(tables["traces"], label, TRACES.names))
        if sum(t.num_rows for t in self.batch) >= TRACE_BATCH:
            self._flush()
        self.left[c.task] -= 1
        if not self.left[c.task]:
            del self.tables[c.task]

    def _flush(self) -> None:
        if self.batch:
            self.traces.write(pa.concat_tables(self.batch))
            self.batch = []

    def commit(self) -> pd.DataFrame:
        table = arrow_table(pa.concat_tables(self.rows)).replace_schema_metadata(None)
        self._flush()
        self.traces.commit()
        write_parquet(self.out / "fault.parquet", table)
        return table.to_pandas()

    def abort(self) -> None:
        self.traces.abort()


TRACE_BATCH = 1 << 17  # rows of traces.parquet written at once (one row group)


def _labelled(table: pa.Table, values: dict[str, str | float], columns: list[str]) -> pa.Table:
    """`table` with `columns`: its own, and each of `values` repeated on every row (text
    dictionary-encoded, written as plain text; numbers as float64)."""
    n = table.num_rows

    def repeated(value: str | float) -> pa.Array:
        if isinstance(value, str):
            return pa.DictionaryArray.from_arrays(pa.array(np.zeros(n, dtype=np.int32)), pa.array([value]))
        return pa.array(np.full(n, value, dtype=np.float64))

    return pa.table({name: repeated(values[name]) if name in values else table.column(name) for name in columns})


@dataclass
class FaultStudy:
    """A finished fault study: its folder (None: none kept), family (config, operating
    point, tasks), the fault table and the engine's record."""

    out: Path | None
    family: FaultFamily
    table: pd.DataFrame
    run: EngineRun

    @property
    def timings(self) -> dict:
        return self.family.timings(self.run.wall_s)


def run_fault_study(
    config: FaultConfig,
    case: Case,
    out: Path | None = None,
    *,
    workers: int | None = 1,
    scheduler: str | None = None,
    fresh: bool = False,
    command: list[str] | None = None,
    reporter: Reporter = SILENT,
) -> FaultStudy:
    """Run the study on the engine into `out` (None: a temporary folder), resuming its
    finished tasks; see `study.engine.run_family` for the rest."""
    run = run_family(
        lambda: plan(config, case), out, workers=workers, scheduler=scheduler, fresh=fresh, command=command, reporter=reporter
    )
    return FaultStudy(out and run.out, run.family, run.result, run)


def simulation_records(table: pd.DataFrame, bus_ids: np.ndarray) -> list[dict]:
    """The `--json` records, one per simulation of a fault table (in its order): fault_bus,
    strategy, k, forecast, variant, status (`recovery_table`'s feeder_status),
    recovery_ms, vmin and margin_pu per bus (by bus number), motors_stalled, sim_ms."""
    ids = [str(int(b)) for b in bus_ids]
    n = len(ids)
    out = []
    for start, summary in zip(range(0, len(table), n), recovery_table(table).itertuples(index=False), strict=True):
        rows = table.iloc[start : start + n]
        rec = [None if np.isnan(r) else round(float(r), 3) for r in rows["recovery_ms"].to_numpy()]
        out.append(
            {
                "fault_bus": int(summary.fault_bus),
                "strategy": summary.strategy,
                "k": float(summary.k),
                "forecast": summary.forecast,
                "variant": summary.variant,
                "status": summary.feeder_status,
                "recovery_ms": dict(zip(ids, rec, strict=True)),
                "vmin": dict(zip(ids, np.round(rows["vmin_pu"].to_numpy(), 6).tolist(), strict=True)),
                "margin_pu": dict(zip(ids, np.round(rows["margin_pu"].to_numpy(), 6).tolist(), strict=True)),
                "motors_stalled": int(summary.motors_stalled),
                "sim_ms": round(float(rows["sim_ms"].iloc[0]), 3),
            }
        )
    return out
