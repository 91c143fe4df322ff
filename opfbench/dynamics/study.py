"""The fault ride-through study: fault buses × strategies × k × forecast × model
variants, run on one operating point, and its tables and files (CONTRACTS.md, fault
folder): `fault.parquet` (one row per simulation × bus), `traces.parquet` (|V| and Q at
the DER buses and the fault bus, 5-ms samples) and `manifest.json`.

Pre-fault setpoints come from the registered strategies (`registry.run_strategy`) on the
same operating point; identical setpoints (no action at every k, a strategy whose k does
not bind) are simulated once and recorded for each configuration.
"""

from __future__ import annotations

import io
import os
import platform
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from opfbench.capability import PAPER_KS, check_reserve
from opfbench.dynamics.model import DynamicModel, build_model, prefault_flow
from opfbench.dynamics.params import FORECASTS, FaultParams, ModelParams
from opfbench.dynamics.simulate import DIVERGED, NOT_RECOVERED, RECOVERED, Simulation, check_fault, simulate
from opfbench.errors import InputError
from opfbench.io import Case
from opfbench.jsonio import write_atomic, write_json
from opfbench.network import Network
from opfbench.registry import get_strategy, run_strategy
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now


@dataclass(frozen=True)
class OperatingPoint:
    """The pre-fault snapshot: `scenario` (forecast P^F = the oracle's, used only by
    forecast-aware strategies with forecast "oracle") and how it was chosen."""

    scenario: Scenario
    label: str


def operating_point(
    net: Network, load_scale: float = 1.0, der_scale: float = 0.8, time: str | None = None, case: Case | None = None
) -> OperatingPoint:
    """Nominal loads × load_scale with every DER at der_scale × rating (the oracle
    forecast of a snapshot is the snapshot itself), or the paper day's minute `time`
    ("HH:MM", local time) with the next minute as the oracle forecast — or, for a `case`
    with its own time series, the step of its profiles at `time` (local date and time,
    e.g. 2016-11-08T12:00) with the next step as the oracle forecast."""
    if time is not None and case is not None and case.series is not None:
        from opfbench.study.periods import local_time

        when = local_time(time, "--time")
        series = case.series
        row = series.index.get_indexer([when])[0]
        if row < 0:
            raise InputError(
                f"--time {time!r} is not a step of {case.spec}'s profiles ({series.index[0]} .. {series.index[-1]}, every {series.step})"
            )
        load_p, load_q, der_p = series.rows(series.index[[row, min(row + 1, len(series.index) - 1)]])
        sc = Scenario.from_series(net, load_p[:1], load_q[:1], der_p[:1], der_p[1:])
        return OperatingPoint(sc, f"{case.spec} profiles at {when.isoformat()}")
    if time is None:
        sc = Scenario.snapshot(net, load_scale, der_scale, forecast_der_scale=der_scale)
        return OperatingPoint(sc, f"load {load_scale:g} × nominal, DER at {der_scale:g} × rating")
    from opfbench.data import paper_day

    day = paper_day()
    hits = np.flatnonzero(day.index.strftime("%H:%M") == time)
    if hits.size == 0:
        raise InputError(f"--time must be HH:MM within the paper day (00:00..23:59), got {time!r}")
    i = int(hits[0])
    j = min(i + 1, len(day) - 1)
    sc = Scenario.from_profiles(
        net,
        day["load"].to_numpy()[i : i + 1],
        day["pv"].to_numpy()[i : i + 1],
        day["wind"].to_numpy()[i : i + 1],
        day["pv"].to_numpy()[j : j + 1],
        day["wind"].to_numpy()[j : j + 1],
    )
    return OperatingPoint(sc, f"paper day {day.index[i].isoformat()}")


@dataclass(frozen=True)
class StudyConfig:
    """What to run. `fault_buses` external bus numbers; `variants` labels understood by
    `ModelParams.with_variant` applied on top of `params`; `fault` the template (its bus
    is replaced by each fault bus)."""

    case: str
    fault_buses: tuple[int, ...]
    strategies: tuple[str, ...] = ("no-action", "llma", "lfma", "acopf")
    ks: tuple[float, ...] = PAPER_KS
    forecasts: tuple[str, ...] = ("off",)
    variants: tuple[str, ...] = ("reference",)
    params: ModelParams = field(default_factory=ModelParams)
    fault: FaultParams = field(default_factory=lambda: FaultParams(bus=0))
    workers: int = 1

    def check(self, net: Network) -> dict[str, ModelParams]:
        """Validate everything before any work starts; return the params of each variant."""
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
        if self.workers < 1:
            raise InputError(f"workers must be ≥ 1, got {self.workers}")
        self.params.check()
        variants = {label: self.params.with_variant(label) for label in self.variants}
        for params in variants.values():
            for b in self.fault_buses:
                check_fault(net, params, replace(self.fault, bus=b))
        return variants


@dataclass(frozen=True)
class SimRecord:
    """One simulation: per-bus arrays (length n_bus, internal order) and its traces."""

    fault_bus: int
    strategy: str
    k: float
    forecast: str
    variant: str
    params: ModelParams
    ok: bool
    recovery_ms: np.ndarray
    vmin_pu: np.ndarray
    margin_pu: np.ndarray
    motors_stalled: int
    sim_ms: float
    trace: pd.DataFrame

    def bus_status(self) -> np.ndarray:
        if not self.ok:
            return np.full(len(self.recovery_ms), DIVERGED, dtype=object)
        return np.where(np.isnan(self.recovery_ms), NOT_RECOVERED, RECOVERED).astype(object)

    @property
    def status(self) -> str:
        st = self.bus_status()
        return DIVERGED if not self.ok else (NOT_RECOVERED if (st == NOT_RECOVERED).any() else RECOVERED)

    def as_json(self, bus_ids: np.ndarray) -> dict:
        """The `--json` record: fault_bus, strategy, k, forecast, status, recovery_ms and
        vmin per bus, motors_stalled, sim_ms (plus variant and the voltage margin)."""
        ids = [str(int(b)) for b in bus_ids]
        rec = [None if np.isnan(r) else round(float(r), 3) for r in self.recovery_ms]
        return {
            "fault_bus": self.fault_bus,
            "strategy": self.strategy,
            "k": self.k,
            "forecast": self.forecast,
            "variant": self.variant,
            "status": self.status,
            "recovery_ms": dict(zip(ids, rec, strict=True)),
            "vmin": dict(zip(ids, np.round(self.vmin_pu, 6).tolist(), strict=True)),
            "margin_pu": dict(zip(ids, np.round(self.margin_pu, 6).tolist(), strict=True)),
            "motors_stalled": self.motors_stalled,
            "sim_ms": round(self.sim_ms, 3),
        }


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


def _simulate_model(job: tuple) -> list[tuple[int, bool, np.ndarray, np.ndarray, np.ndarray, int, float, pd.DataFrame]]:
    """Worker: every fault of one model → per-fault measures (picklable)."""
    model, faults = job
    out = []
    for fault in faults:
        sim = simulate(model, fault)
        out.append(
            (fault.bus, sim.ok, sim.recovery_ms(), sim.vmin(), sim.margin_pu(), sim.motors_stalled(), sim.sim_ms, _trace(sim))
        )
    return out


def run_study(config: StudyConfig, point: OperatingPoint, progress=None) -> tuple[list[SimRecord], dict]:
    """Run the study; returns the records and the timings {"study_s", "simulations", "models"}."""
    net = point.scenario.net
    variants = config.check(net)
    start = now()
    faults = [replace(config.fault, bus=b) for b in config.fault_buses]
    setpoints: dict[tuple[str, float, str], np.ndarray] = {}
    for fc in config.forecasts:
        sc = point.scenario if fc == "oracle" else point.scenario.without_forecast()
        for name in config.strategies:
            if fc != "off" and not get_strategy(name).uses_forecast:
                continue
            for k in config.ks:
                res = run_strategy(name, sc, k)
                if res.status[0] not in ("ok",) and not str(res.status[0]).startswith("fallback"):
                    raise InputError(f"strategy {name} at k = {k:g} gave status {res.status[0]} on this operating point")
                setpoints[name, k, fc] = res.q_mvar[0]
    sc_off = point.scenario.without_forecast()
    jobs: list[tuple[DynamicModel, list[FaultParams]]] = []
    keys = []
    for label, params in variants.items():
        emf = params.source.emf_pu if params.source.emf == "given" else None
        if params.source.emf == "held":
            emf = abs(prefault_flow(sc_off, np.zeros(len(net.ders)), params)[1])
        unique: dict[bytes, int] = {}
        for (name, k, fc), q in setpoints.items():
            key = np.round(q, 12).tobytes()
            if key not in unique:
                unique[key] = len(jobs)
                jobs.append((build_model(sc_off, q, params, emf), faults))
            keys.append((label, params, name, k, fc, unique[key]))
    if progress:
        progress(f"{len(jobs)} distinct models × {len(faults)} fault buses")
    if config.workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(config.workers) as pool:
            results = list(pool.map(_simulate_model, jobs))
    else:
        results = [_simulate_model(j) for j in jobs]
    records = []
    for label, params, name, k, fc, j in keys:
        for bus, ok, rec, vmin, margin, stalled, ms, trace in results[j]:
            records.append(SimRecord(bus, name, float(k), fc, label, params, ok, rec, vmin, margin, stalled, ms, trace))
    return records, {"study_s": elapsed_ms(start) / 1e3, "simulations": len(jobs) * len(faults), "models": len(jobs)}


def fault_table(records: list[SimRecord], net: Network, case: str) -> pd.DataFrame:
    """The `fault.parquet` table: one row per (simulation, bus)."""
    der = set(int(b) for b in net.bus_ids[net.der_bus])
    rows = []
    for r in records:
        src = r.params.source
        base = {
            "case": case,
            "fault_bus": r.fault_bus,
            "strategy": r.strategy,
            "k": r.k,
            "forecast": r.forecast,
            "variant": r.variant,
            "source_impedance_pu": src.impedance_pu,
            "emf": src.emf,
            "motor_share": r.params.motors.share,
        }
        status = r.bus_status()
        for i, b in enumerate(net.bus_ids):
            rows.append(
                base
                | {
                    "bus": int(b),
                    "recovery_ms": r.recovery_ms[i],
                    "status": status[i],
                    "vmin_pu": r.vmin_pu[i],
                    "margin_pu": r.margin_pu[i],
                    "motors_stalled": r.motors_stalled,
                    "sim_ms": r.sim_ms,
                    "der_bus": int(b) in der,
                    "faulted": int(b) == r.fault_bus,
                }
            )
    return pd.DataFrame(rows)


def trace_table(records: list[SimRecord], case: str) -> pd.DataFrame:
    """The `traces.parquet` table (long): case, fault_bus, strategy, k, forecast, variant,
    bus, t_s, v_pu, q_mvar."""
    parts = [
        r.trace.assign(case=case, fault_bus=r.fault_bus, strategy=r.strategy, k=r.k, forecast=r.forecast, variant=r.variant)
        for r in records
    ]
    cols = ["case", "fault_bus", "strategy", "k", "forecast", "variant", "bus", "t_s", "v_pu", "q_mvar"]
    return pd.concat(parts, ignore_index=True)[cols] if parts else pd.DataFrame(columns=cols)


def _write_parquet(path: Path, df: pd.DataFrame) -> None:
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    write_atomic(path, buf.getvalue())


def write_study(
    out: Path, records: list[SimRecord], config: StudyConfig, point: OperatingPoint, timings: dict, command: list[str]
) -> list[Path]:
    """Write fault.parquet, traces.parquet and manifest.json into `out`."""
    import numba
    import scipy

    from opfbench import __version__

    out.mkdir(parents=True, exist_ok=True)
    net = point.scenario.net
    _write_parquet(out / "fault.parquet", fault_table(records, net, config.case))
    _write_parquet(out / "traces.parquet", trace_table(records, config.case))
    fault = asdict(config.fault)
    fault.pop("bus")
    manifest = {
        "schema": 1,
        "opfbench_version": __version__,
        "command": command,
        "created_utc": pd.Timestamp.now(tz="UTC").isoformat(),
        "case": config.case,
        "operating_point": point.label,
        "config": {
            "fault_buses": list(config.fault_buses),
            "strategies": list(config.strategies),
            "ks": list(config.ks),
            "forecasts": list(config.forecasts),
            "variants": list(config.variants),
        },
        "model": config.params.as_dict(),
        "variants": {label: config.params.with_variant(label).as_dict() for label in config.variants},
        "fault": fault,
        "integrator": {
            "method": "classical Runge–Kutta (RK4), fixed step",
            "step_s": config.fault.step_s,
            "network": "current injection, fixed point over the DER buses to 1e-12 p.u.",
        },
        "recovery": {"threshold_pu": 0.9, "margin_window_s": 0.1, "trace_step_s": 0.005},
        "timings": timings,
        "versions": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "pandas": pd.__version__,
            "numba": numba.__version__,
        },
        "machine": {"cores": os.cpu_count(), "platform": platform.platform()},
        "files": {
            "fault.parquet": "one row per (simulation, bus)",
            "traces.parquet": "|V| and Q at the DER buses and the fault bus, 5-ms samples",
        },
    }
    write_json(out / "manifest.json", manifest)
    return [out / "fault.parquet", out / "traces.parquet", out / "manifest.json"]


def recovery_summary(table: pd.DataFrame) -> pd.DataFrame:
    """One row per (variant, fault_bus, strategy, k, forecast) of a `fault.parquet` table:
    recovery at the fault bus and the feeder's recovery (the slowest bus), that bus's
    voltage margin, and both recoveries minus no action's in the same variant and fault
    (ms; positive = slower than no action)."""
    keys = ["variant", "fault_bus", "strategy", "k", "forecast"]
    t = table.assign(rec=table["recovery_ms"].fillna(np.inf))
    worst = t.loc[t.groupby(keys, sort=False)["rec"].idxmax(), keys + ["bus", "recovery_ms", "margin_pu"]]
    worst = worst.rename(columns={"bus": "slowest_bus", "recovery_ms": "feeder_recovery_ms", "margin_pu": "slowest_margin_pu"})
    at_fault = table.loc[table["faulted"], keys + ["recovery_ms", "vmin_pu", "motors_stalled"]]
    out = at_fault.rename(columns={"recovery_ms": "fault_bus_recovery_ms", "vmin_pu": "fault_bus_vmin_pu"})
    out = out.merge(worst, on=keys)
    base = (
        out[out["strategy"] == "no-action"]
        .groupby(["variant", "fault_bus"])[["fault_bus_recovery_ms", "feeder_recovery_ms"]]
        .first()
    )
    base.columns = ["na_fault", "na_feeder"]
    out = out.join(base, on=["variant", "fault_bus"])
    out["delta_fault_bus_ms"] = out["fault_bus_recovery_ms"] - out.pop("na_fault")
    out["delta_feeder_ms"] = out["feeder_recovery_ms"] - out.pop("na_feeder")
    return out.reset_index(drop=True)


def case_source(case: Case, params: ModelParams) -> ModelParams:
    """`params` with the upstream source of `case`'s short-circuit data, where it has some:
    |Z| = base_mva / S″k (p.u. on the case base, the Thevenin impedance of the upstream grid
    at rated voltage, IEC 60909 with c = 1), split by its R/X ratio."""
    if case.short_circuit is None:
        return params
    s_sc, rx = case.short_circuit
    z = case.network.base_mva / s_sc
    x = z / np.hypot(1.0, rx)
    return replace(params, source=replace(params.source, impedance_pu=float(x), resistance_pu=float(rx * x)))
