"""Every table opfbench writes, declared once: each column's name, type, unit and meaning,
in the order of the file. The writers build their tables from these declarations (the
per-step table computes each column from its declaration), the readers check them against
them, and `docs/CONTRACTS.md` holds them as generated here (`python -m opfbench.schema`
rewrites its tables; `tests/test_contracts.py` checks the page against this module).

Adding a column is one edit: a `Column` in its table — for the per-step table with the
function that computes it from a `StepContext` (a strategy's result on a task's steps); a
summary column also needs its sum in `study.run_tables`. Types are the page's: text, number
(a float), integer, true/false, time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from opfbench.result import MAX_VUF, STATUSES, VM_ERROR, Reference

if TYPE_CHECKING:
    from opfbench.result import StrategyResult

Dtype = Literal["text", "number", "integer", "true/false", "time"]
NO_UNIT = "—"


@dataclass(frozen=True)
class StepContext:
    """What a per-step column is computed from: a strategy's result on a task's steps and
    the task's labels. `time` (UTC ns, int64), `night` (S,) bool; `reference` each step's
    frontier point at the strategy's own compliance (None: no frontier, NaN columns)."""

    case: str
    night_mode: str
    forecast: str
    time: np.ndarray
    step_h: float
    night: np.ndarray
    res: StrategyResult
    reference: Reference | None = None

    @property
    def frontier(self) -> Reference:
        """`reference`, or NaN points (not curtailing) where there is none."""
        if self.reference is not None:
            return self.reference
        nan = np.full(self.res.n_snapshots, np.nan)
        return Reference(nan, nan, nan, np.zeros(self.res.n_snapshots, dtype=bool), np.full(self.res.n_snapshots, ""))


Value = Callable[[StepContext], Any]  # one value for every row, or an array of the rows


@dataclass(frozen=True)
class Column:
    """A declared column: `name`, `dtype`, `unit` (NO_UNIT: none), `meaning`; `value` how
    the per-step table computes it (per-step columns only)."""

    name: str
    dtype: Dtype
    unit: str
    meaning: str
    value: Value | None = dataclasses.field(default=None, compare=False, repr=False)

    def as_in(self, table: str) -> Column:
        """The same column in another table, its meaning referring to `table`'s."""
        return Column(self.name, self.dtype, self.unit, f"as in `{table}`")

    def row(self) -> str:
        """The column as a row of the page's table."""
        return f"| `{self.name}` | {self.dtype} | {self.unit} | {self.meaning.replace('|', chr(92) + '|')} |"


@dataclass(frozen=True)
class Table:
    """A declared table: the file it is (as the page names it) and its columns in order;
    `extra`: the page's row for columns the run's strategies add (`<extra>`), if any."""

    file: str
    columns: tuple[Column, ...]
    extra: Column | None = None

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.columns]

    def __getitem__(self, name: str) -> Column:
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(f"{self.file} has no column {name!r}")

    def __iter__(self) -> Iterator[Column]:
        return iter(self.columns)

    def compute(self, context: StepContext) -> dict[str, Any]:
        """Every column computed from `context` by its declaration (a per-step table)."""
        out = {}
        for c in self.columns:
            if c.value is None:
                raise TypeError(f"{self.file}: column {c.name} declares no value")
            out[c.name] = c.value(context)
        return out

    def markdown(self) -> str:
        """The page's table of this file."""
        rows = [c.row() for c in (*self.columns, *((self.extra,) if self.extra else ()))]
        return "\n".join(["| column | type | unit | meaning |", "|---|---|---|---|", *rows])


def _keys(table: str | None = None) -> tuple[Column, ...]:
    """The configuration's key columns (`steps.parquet`'s, or as in it)."""
    keys = (
        Column(
            "case",
            "text",
            NO_UNIT,
            "the case spec (`opfbench.io.sources`: a shipped name, a file path, `simbench:CODE`, with `?der=…` options)",
            lambda c: c.case,
        ),
        Column("strategy", "text", NO_UNIT, "the registered strategy (configuration label)", lambda c: c.res.strategy),
        Column("k", "number", NO_UNIT, "the reserve coefficient k in [0, 1]", lambda c: float(c.res.k)),
        Column("night_mode", "text", NO_UNIT, "connected, disconnected or connected-q", lambda c: c.night_mode),
        Column("forecast", "text", NO_UNIT, "off, oracle or a forecasting model's name", lambda c: c.forecast),
    )
    return keys if table is None else tuple(k.as_in(table) for k in keys)


def _nan(c: StepContext) -> np.ndarray:
    return np.full(c.res.n_snapshots, np.nan)


def _solver(field: str, dtype: type, local: object) -> Value:
    """A formulation's solver record field (`result.SolverRecord`); `local` for a local rule."""

    def value(c: StepContext) -> Any:
        record = c.res.solver
        if record is None:
            return local(c) if callable(local) else local
        return np.asarray(getattr(record, field), dtype=dtype)

    return value


STEPS = Table(
    "steps.parquet",
    (
        *_keys(),
        Column("time", "time", NO_UNIT, "the step's start (local time)", lambda c: c.time),
        Column("step_h", "number", "h", "the step's length", lambda c: float(c.step_h)),
        Column("night", "true/false", NO_UNIT, "the step lies in the night window", lambda c: np.asarray(c.night, dtype=bool)),
        Column(
            "status",
            "text",
            NO_UNIT,
            f"{', '.join(STATUSES)} (`opfbench.result.STATUSES`)",
            lambda c: c.res.status.astype(str),
        ),
        Column(
            "losses_kw",
            "number",
            "kW",
            "active losses of the AC power flow at the setpoints; NaN where it did not converge",
            lambda c: c.res.losses_kw,
        ),
        Column("vmin_pu", "number", "p.u.", "lowest bus |V| (NaN where the flow did not converge)", lambda c: c.res.vmin),
        Column("vmax_pu", "number", "p.u.", "highest bus |V| (NaN likewise)", lambda c: c.res.vmax),
        Column(
            "max_vuf_pct",
            "number",
            "%",
            "worst voltage unbalance factor |V₂|/|V₁| at a three-phase bus (three-phase feeders; NaN on balanced cases "
            "and where the flow did not converge)",
            lambda c: np.asarray(c.res.extra.get(MAX_VUF, _nan(c)), dtype=float),
        ),
        Column(
            "voltage_violation_pu",
            "number",
            "p.u.",
            "largest excursion beyond the buses' voltage limits (0 if none)",
            lambda c: c.res.voltage_violation(),
        ),
        Column(
            "q_total_mvar", "number", "MVAr", "sum of the DER setpoints (positive = injected)", lambda c: c.res.q_mvar.sum(axis=1)
        ),
        Column(
            "curtailed_kw",
            "number",
            "kW",
            "active power the DER had available and did not deliver (Volt-Watt, reactive priority); 0 for a strategy "
            "that curtails nothing, NaN where it gave no setpoint",
            lambda c: c.res.curtailed_kw,
        ),
        Column(
            "excursion_mvar",
            "number",
            "MVAr",
            "largest amount by which a setpoint exceeds its DER's capability at the current P",
            lambda c: c.res.excursion_mvar,
        ),
        Column(
            "lower_bound_kw",
            "number",
            "kW",
            "certified lower bound on the losses (formulations; on losses + curtailed power for one that curtails), NaN "
            "where none",
            lambda c: _nan(c) if c.res.lower_bound_kw is None else np.asarray(c.res.lower_bound_kw, dtype=float),
        ),
        Column(
            "power_flows",
            "integer",
            NO_UNIT,
            "AC power flows the strategy used for the step",
            lambda c: np.asarray(c.res.power_flows, dtype=np.int64),
        ),
        Column(
            "wall_ms",
            "number",
            "ms",
            "wall time of the step (the strategy's batch time over its steps)",
            lambda c: c.res.wall_ms / c.res.n_snapshots,
        ),
        Column(
            "solver_ms",
            "number",
            "ms",
            "the solver's own time (formulations), NaN for the local rules",
            _solver("solve_ms", float, _nan),
        ),
        Column(
            "iterations",
            "number",
            NO_UNIT,
            "solver iterations (formulations), NaN for the local rules",
            _solver("iterations", float, _nan),
        ),
        Column(
            "certified_by",
            "text",
            NO_UNIT,
            "socp or ipopt (balanced feeders), sdp3 or unique (three-phase: the SDP bound, or no decision and the power flow's point proven the only one): what certified the point optimal; empty if nothing",
            _solver("certified_by", str, ""),
        ),
        Column(
            "fallback",
            "text",
            NO_UNIT,
            "which fallback gave the point (formulations); empty otherwise",
            _solver("fallback", str, ""),
        ),
        Column(
            "solver_status",
            "text",
            NO_UNIT,
            "the solver's own status text (formulations; `bounds: the slack must export` or `bounds: voltage limits out of "
            "reach` where the interval bounds proved the step infeasible without a solver); empty otherwise",
            _solver("solver_status", str, ""),
        ),
        Column(
            "vm_error_pu",
            "number",
            "p.u.",
            "an approximation's largest error of the voltages it predicts against the power flow's at its setpoints "
            "(`lindist3flow`); NaN for the other strategies and where it gave no point",
            lambda c: np.asarray(c.res.extra.get(VM_ERROR, _nan(c)), dtype=float),
        ),
        Column(
            "frontier_kw",
            "number",
            "kW",
            "the frontier's optimum (losses + curtailed power) at the smallest grid ε covering the step's voltage "
            "excursion: the reference at equal compliance; NaN where that ε has no optimum (or the step no figure)",
            lambda c: c.frontier.cost_kw,
        ),
        Column(
            "frontier_bound_kw",
            "number",
            "kW",
            "that frontier point's certified bound (the relaxation's); NaN where not solved",
            lambda c: c.frontier.bound_kw,
        ),
        Column("frontier_eps_pu", "number", "p.u.", "that ε (`inf`: the physical limits alone)", lambda c: c.frontier.eps_pu),
        Column(
            "frontier_curtails",
            "true/false",
            NO_UNIT,
            "that frontier is the optimum's that may curtail (`acopf:curtail=true`): the reference of a configuration "
            "that curtails",
            lambda c: np.asarray(c.frontier.curtails, dtype=bool),
        ),
        Column(
            "frontier_limit",
            "text",
            NO_UNIT,
            "what that frontier's DER may use: `reserve` (1 − k)·Qmax(P), the configuration's own limits; `forecast` "
            "Algorithm 3's limit of its forecast source, capped at Qmax(P) (where its setpoints used the reserve); "
            "`capability` Qmax(P), k = 0 (where they exceed that too); empty where a setpoint exceeds Qmax(P) itself "
            "(no frontier bounds a point no inverter can deliver: `frontier_kw` is NaN)",
            lambda c: np.asarray(c.frontier.limit, dtype=str),
        ),
    ),
    extra=Column(
        "<extra>",
        "number",
        NO_UNIT,
        "the extra columns the run's strategies declare (the registry's `columns`, e.g. `residual_mvar`, MVAr, of the "
        "closed-loop rules), each once",
    ),
)
"""One row per case × strategy × k × night mode × forecast × step (`study.run_tables.step_rows`)."""

KEYS = [c.name for c in _keys()]

DER_Q = Table(
    "der_q.parquet",
    (
        *_keys("steps.parquet"),
        Column("time", "time", NO_UNIT, "the step's start"),
        Column("der", "text", NO_UNIT, "the DER's name, unique in its case (the source's element name, else `KIND-BUS`)"),
        Column(
            "bus",
            "integer",
            NO_UNIT,
            "the DER's bus (the case's bus number; on a three-phase feeder the bus's position in the feeder's bus list, "
            "its OpenDSS name being in the DER's name; several DER may share one)",
        ),
        Column("kind", "text", NO_UNIT, "the DER's kind (PV, DFIG, inverter)"),
        Column("q_mvar", "number", "MVAr", "its reactive setpoint (positive = injected)"),
        Column("curtailed_mw", "number", "MW", "the active power it had available and did not deliver"),
    ),
)
"""One row per configuration × step × DER (`study.run_tables.detail_rows`)."""

BUS_V = Table(
    "bus_v.parquet",
    (
        *_keys("steps.parquet"),
        Column("time", "time", NO_UNIT, "the step's start"),
        Column("bus", "integer", NO_UNIT, "the bus number"),
        Column("v_pu", "number", "p.u.", "its |V| (NaN where the flow did not converge)"),
    ),
)
"""One row per configuration × step × bus (`study.run_tables.detail_rows`)."""

TASK_SUMMARY = Table(
    "tasks/<id>.summary.parquet",
    (
        *_keys("steps.parquet"),
        Column("steps", "integer", NO_UNIT, "the task's steps of the configuration"),
        Column("hours", "number", "h", "their length"),
        Column(
            "pf_converged_steps", "integer", NO_UNIT, "steps with a figure (a converged power flow at the strategy's setpoints)"
        ),
        Column("measured_hours", "number", "h", "their length"),
        Column("energy_kwh", "number", "kWh", "sum of losses × step length over the steps with a figure"),
        Column("curtailed_kwh", "number", "kWh", "sum of curtailed power × step length"),
        Column("frontier_kwh", "number", "kWh", "sum of `frontier_kw` × step length over the steps that have one"),
        Column("frontier_missing", "integer", NO_UNIT, "steps without a frontier optimum"),
        Column("frontier_bound_kwh", "number", "kWh", "sum of `frontier_bound_kw` × step length over the steps that have one"),
        Column("frontier_bound_missing", "integer", NO_UNIT, "steps without a frontier bound"),
        Column(
            "below_frontier_steps",
            "integer",
            NO_UNIT,
            "steps whose cost (losses + curtailed) lies more than 1e-4 kW below `frontier_kw`",
        ),
        Column("frontier_curtails", "true/false", NO_UNIT, "as in `steps.parquet`"),
        Column(
            "reserve_used_steps",
            "integer",
            NO_UNIT,
            "steps whose setpoints used the reserve (`frontier_limit` forecast or capability)",
        ),
        Column("not_ok_steps", "integer", NO_UNIT, "steps whose status is not ok"),
        Column("not_settled_steps", "integer", NO_UNIT, "steps where a closed-loop rule did not settle"),
        Column("pf_diverged_steps", "integer", NO_UNIT, "steps of status pf-diverged"),
        Column("rule_non_finite_steps", "integer", NO_UNIT, "steps of status rule-non-finite"),
        Column("voltage_violation_steps", "integer", NO_UNIT, "steps violating a voltage limit by more than 1e-6 p.u."),
        Column("voltage_violation_h", "number", "h", "their length"),
        Column("max_violation_pu", "number", "p.u.", "the worst excursion beyond the limits"),
        Column("vmin_pu", "number", "p.u.", "lowest |V|"),
        Column("vmax_pu", "number", "p.u.", "highest |V|"),
        Column("max_vuf_pct", "number", "%", "worst voltage unbalance factor"),
        Column("vuf_h", "number", "h", "length of the steps whose worst VUF exceeds EN 50160's 2 %"),
        Column("max_excursion_mvar", "number", "MVAr", "largest capability excursion"),
        Column("excursion_steps", "integer", NO_UNIT, "steps with an excursion beyond 1e-9 MVAr"),
        Column("lower_bound_kwh", "number", "kWh", "sum of the bound × step length"),
        Column("lb_missing", "integer", NO_UNIT, "steps without a bound"),
        Column("wall_s", "number", "s", "wall time"),
        Column("solver_s", "number", "s", "solver time"),
        Column("solver_known", "integer", NO_UNIT, "steps with a solver time"),
        Column("certified", "integer", NO_UNIT, "steps whose point is certified optimal"),
    ),
)
"""A task's partial sums per configuration (`study.run_tables.partial_summary`), combined into
the summary by `study.run_tables.summarize`."""

SUMMARY = Table(
    "summary.csv",
    (
        *_keys("steps.parquet")[:2],
        Column("k", "number", NO_UNIT, "as in `steps.parquet` (written exactly: 0.1 and 0.1000001 are two rows)"),
        *_keys("steps.parquet")[3:],
        Column("steps", "integer", NO_UNIT, "steps of the period"),
        Column("hours", "number", "h", "the period's length"),
        Column("avg_loss_kw", "number", "kW", "average losses over the steps with a converged power flow"),
        Column("energy_kwh", "number", "kWh", "the period's energy losses; empty unless every step has a figure"),
        Column("no_action_kwh", "number", "kWh", "no action's energy in the same case, k and night mode, forecast off"),
        Column("savings_pct", "number", "%", "100 · (1 − energy / no action's)"),
        Column("curtailed_kwh", "number", "kWh", "active energy the DER had available and did not deliver"),
        Column("cost_kwh", "number", "kWh", "energy + curtailed energy: what the frontier bounds"),
        Column(
            "frontier_kwh",
            "number",
            "kWh",
            "the frontier's optimum at the configuration's own compliance, step by step (empty unless every step has one)",
        ),
        Column("frontier_bound_kwh", "number", "kWh", "its certified bound (empty unless every step has one)"),
        Column(
            "gap_eq_kwh",
            "number",
            "kWh",
            "the gap at equal compliance: cost − frontier (≥ 0 where the optimum is global and the point in the OPF's set)",
        ),
        Column("gap_eq_pct", "number", "%", "100 · gap at equal compliance / frontier"),
        Column(
            "share_eq_pct",
            "number",
            "%",
            "the share at equal compliance: 100 · (no action's energy − cost) / (no action's energy − frontier), ≤ 100; "
            "empty where that reduction is below 1e-6 kWh",
        ),
        Column(
            "share_pct",
            "number",
            "%",
            "the plain, loss-only share: 100 · (no action's energy − energy) / (no action's energy − the AC OPF's), which "
            "compares with an optimum that holds the band whatever the configuration does; empty without an AC OPF row "
            "or where it reduces nothing",
        ),
        Column(
            "frontier_curtails",
            "true/false",
            NO_UNIT,
            "its frontier is the optimum's that may curtail (a configuration that curtails: Volt-Watt, reactive "
            "priority, `acopf:curtail=true`)",
        ),
        Column(
            "frontier_missing_steps",
            "integer",
            NO_UNIT,
            "steps without a frontier optimum at their compliance (none at their ε, or setpoints beyond the DER's "
            "capability: `excursion_steps`)",
        ),
        Column(
            "reserve_used_steps",
            "integer",
            NO_UNIT,
            "steps whose setpoints used the reserve k (within the DER's capability), compared with the frontier at the "
            "capability they used (`frontier_limit` in `steps.parquet`)",
        ),
        Column(
            "below_frontier_steps",
            "integer",
            NO_UNIT,
            "steps whose cost lies below their frontier point (a rule outside the OPF's set, or an optimum that is not global)",
        ),
        Column("not_ok_steps", "integer", NO_UNIT, "steps whose status is not ok"),
        Column("not_settled_steps", "integer", NO_UNIT, "steps where a closed-loop rule did not settle"),
        Column("voltage_violation_steps", "integer", NO_UNIT, "steps violating a voltage limit (of the converged ones)"),
        Column("voltage_violation_min", "number", "min", "minutes of steps outside the case's voltage limits"),
        Column("max_violation_pu", "number", "p.u.", "the worst excursion beyond them"),
        Column("vmin_pu", "number", "p.u.", "lowest |V| over the converged steps"),
        Column("vmax_pu", "number", "p.u.", "highest |V| over the converged steps"),
        Column("max_vuf_pct", "number", "%", "worst voltage unbalance factor |V₂|/|V₁| (three-phase feeders)"),
        Column("vuf_min", "number", "min", "minutes of steps whose worst VUF exceeds EN 50160's 2 %"),
        Column("max_excursion_mvar", "number", "MVAr", "largest capability excursion"),
        Column("excursion_steps", "integer", NO_UNIT, "steps with an excursion"),
        Column(
            "lower_bound_kwh",
            "number",
            "kWh",
            "the SOCP bound (slack may export) over the same steps, from the socp rows (else acopf's)",
        ),
        Column("gap_kwh", "number", "kWh", "energy − lower bound"),
        Column("gap_pct", "number", "%", "100 · gap / lower bound"),
        Column("wall_s", "number", "s", "wall time"),
        Column("solver_s", "number", "s", "solver time (empty for the local rules)"),
        Column("certified_share", "number", NO_UNIT, "share of steps certified optimal"),
        Column(
            "pf_converged_steps",
            "integer",
            NO_UNIT,
            "steps with a figure (a converged power flow at the strategy's setpoints): the steps the averages are over",
        ),
        Column(
            "pf_diverged_steps", "integer", NO_UNIT, "steps of status pf-diverged: the power flow did not converge (no figure)"
        ),
        Column(
            "rule_non_finite_steps",
            "integer",
            NO_UNIT,
            "steps of status rule-non-finite: the rule gave NaN or inf, no setpoint (no figure)",
        ),
    ),
)
"""One row per configuration (`study.run_tables.summarize`); figures written to 6 significant digits."""

_CURTAIL = Column(
    "curtail",
    "true/false",
    NO_UNIT,
    "the frontier of the optimum that may curtail (objective losses + curtailed power), or of the plain AC OPF",
)
_FRONTIER_KEYS = (*_keys("steps.parquet")[:1], *_keys("steps.parquet")[2:4], _CURTAIL)

FRONTIER = Table(
    "frontier.parquet",
    (
        *_FRONTIER_KEYS,
        Column("time", "time", NO_UNIT, "the step's start"),
        Column("step_h", "number", "h", "the step's length"),
        Column("eps_pu", "number", "p.u.", "the band's widening ε (`inf`: the physical limits alone)"),
        Column(
            "cost_kw",
            "number",
            "kW",
            "the AC OPF's optimum (losses, + curtailed power where it curtails) with the band widened by ε; NaN where "
            "there is none (infeasible, or only a fallback point)",
        ),
        Column("bound_kw", "number", "kW", "its certified bound (the relaxation's); NaN where not solved"),
        Column("excursion_pu", "number", "p.u.", "the optimum's largest excursion beyond the unwidened band"),
        Column("status", "text", NO_UNIT, "the AC OPF's status of the point (`opfbench.result.STATUSES`)"),
        Column("solved", "true/false", NO_UNIT, "solved at this ε (false: the answer of another ε that covers it)"),
    ),
)
"""One row per case × k × night mode × step × ε (`study.run_tables.frontier_rows`): the
frontier of losses against compliance (`formulations.frontier`)."""

TASK_FRONTIER_SUMMARY = Table(
    "tasks/<id>.frontier_summary.parquet",
    (
        *_FRONTIER_KEYS,
        Column("eps_pu", "number", "p.u.", "as in `frontier.parquet`"),
        Column("steps", "integer", NO_UNIT, "the task's steps"),
        Column("energy_kwh", "number", "kWh", "sum of cost × step length over the steps with an optimum"),
        Column("missing", "integer", NO_UNIT, "steps without an optimum"),
        Column("bound_kwh", "number", "kWh", "sum of the bound × step length"),
        Column("bound_missing", "integer", NO_UNIT, "steps without a bound"),
        Column("outside_h", "number", "h", "length of the steps whose optimum lies outside the unwidened band"),
        Column("max_excursion_pu", "number", "p.u.", "the optimum's worst excursion beyond it"),
        Column("solved", "integer", NO_UNIT, "steps solved at this ε"),
    ),
)
"""A task's frontier sums per case, k, night mode and ε (`study.run_tables.partial_frontier`),
combined into the frontier's summary by `study.run_tables.summarize_frontier`."""

FRONTIER_SUMMARY = Table(
    "frontier.csv",
    (
        _FRONTIER_KEYS[0],
        Column("k", "number", NO_UNIT, "as in `summary.csv`"),
        *_FRONTIER_KEYS[2:],
        Column("eps_pu", "number", "p.u.", "as in `frontier.parquet`"),
        Column("steps", "integer", NO_UNIT, "steps of the period"),
        Column(
            "energy_kwh",
            "number",
            "kWh",
            "the optimum's energy over the period with the band widened by ε (empty unless every step has an optimum)",
        ),
        Column("bound_kwh", "number", "kWh", "its certified bound (empty unless every step has one)"),
        Column("no_optimum_steps", "integer", NO_UNIT, "steps without an optimum at this ε"),
        Column("voltage_violation_min", "number", "min", "minutes the optimum lies outside the unwidened band"),
        Column("max_violation_pu", "number", "p.u.", "its worst excursion beyond it"),
        Column(
            "solved_steps", "integer", NO_UNIT, "steps solved at this ε (the others take the answer of an ε that covers them)"
        ),
    ),
)
"""One row per case × k × night mode × ε (`study.run_tables.summarize_frontier`); figures
written to 6 significant digits."""

_FAULT_LABELS = (
    Column("case", "text", NO_UNIT, "the case spec"),
    Column("fault_bus", "integer", NO_UNIT, "the faulted bus (bus number)"),
    Column("strategy", "text", NO_UNIT, "the strategy whose setpoints the DER hold before the fault"),
    Column("k", "number", NO_UNIT, "reserve coefficient"),
    Column("forecast", "text", NO_UNIT, "off or oracle"),
    Column("variant", "text", NO_UNIT, "the model variant (reference, or key=value[,key=value])"),
)
_FAULT_MEASURES = (
    Column("recovery_ms", "number", "ms", "from fault inception until |V| ≥ 0.9 p.u. for good; NaN: not recovered"),
    Column("status", "text", NO_UNIT, "recovered, not-recovered or diverged"),
    Column("vmin_pu", "number", "p.u.", "lowest |V| from inception on"),
    Column("margin_pu", "number", "p.u.", "min |V| − 0.9 over the last 100 ms"),
    Column("motors_stalled", "integer", NO_UNIT, "motors beyond breakdown slip at the end (of the simulation)"),
    Column("sim_ms", "number", "ms", "wall time of the simulation"),
    Column("der_bus", "true/false", NO_UNIT, "the bus has a DER"),
    Column("faulted", "true/false", NO_UNIT, "the bus is the faulted one"),
)
FAULT = Table(
    "fault.parquet",
    (
        *_FAULT_LABELS,
        Column("source_impedance_pu", "number", "p.u.", "the upstream source reactance of the variant"),
        Column("emf", "text", NO_UNIT, "the source EMF mode (reset, held, given)"),
        Column("motor_share", "number", NO_UNIT, "share of each load's P in motors"),
        Column("bus", "integer", NO_UNIT, "the bus this row is of"),
        *_FAULT_MEASURES,
    ),
)
"""One row per simulation × bus (`dynamics.study`)."""

TRACES = Table(
    "traces.parquet",
    (
        *(c.as_in(FAULT.file) for c in _FAULT_LABELS),
        Column("bus", "integer", NO_UNIT, "a DER bus or the fault bus"),
        Column("t_s", "number", "s", "time from the start of the simulation"),
        Column("v_pu", "number", "p.u.", "|V| at the bus"),
        Column("q_mvar", "number", "MVAr", "the DER's Q (positive = injected); NaN at a bus without DER"),
    ),
)
"""|V| and Q at the DER buses and the fault bus, 5-ms samples (`dynamics.study`)."""

FAULT_TASK = Table(
    "tasks/<id>.parquet",
    (
        Column("fault_bus", "integer", NO_UNIT, "the faulted bus"),
        Column("bus", "integer", NO_UNIT, "the bus this row is of"),
        *(c.as_in(FAULT.file) for c in _FAULT_MEASURES),
    ),
)
"""A fault task's per-bus measures, before the labels of its configurations."""

FAULT_TASK_TRACES = Table(
    "tasks/<id>.traces.parquet",
    (*(c.as_in(TRACES.file) for c in TRACES.columns[-4:]), Column("fault_bus", "integer", NO_UNIT, "the faulted bus")),
)
"""A fault task's traces, before the labels of its configurations."""

#: The declared tables by folder kind, in the page's order.
TABLES: dict[str, tuple[Table, ...]] = {
    "run": (STEPS, DER_Q, BUS_V, TASK_SUMMARY, SUMMARY, FRONTIER, TASK_FRONTIER_SUMMARY, FRONTIER_SUMMARY),
    "fault": (FAULT, TRACES, FAULT_TASK, FAULT_TASK_TRACES),
}


def contracts_page(text: str) -> str:
    """The page `text` (docs/CONTRACTS.md) with the table under each declared file's
    heading (`### \\`FILE\\`` in its folder's section) written from the declaration."""
    sections = {"run": "## Run folder", "fault": "## Fault folder"}
    lines, out, folder, i = text.splitlines(), [], None, 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        i += 1
        if line.startswith("## "):
            folder = next((kind for kind, head in sections.items() if line.startswith(head)), None)
            continue
        table = next((t for t in TABLES.get(folder or "", ()) if line == f"### `{t.file}`"), None)
        if table is None:
            continue
        while i < len(lines) and not lines[i].startswith("| column |"):  # the text between heading and table
            if lines[i].startswith("#"):
                raise ValueError(f"CONTRACTS.md: {table.file} ({folder} folder) has no column table")
            out.append(lines[i])
            i += 1
        while i < len(lines) and lines[i].startswith("|"):  # the old table
            i += 1
        out.extend(table.markdown().splitlines())
    return "\n".join(out) + ("\n" if text.endswith("\n") else "")


if __name__ == "__main__":  # python -m opfbench.schema docs/CONTRACTS.md: its tables rewritten from the declarations
    import sys
    from pathlib import Path

    for name in sys.argv[1:]:
        page = Path(name)
        page.write_text(contracts_page(page.read_text(encoding="utf-8")), encoding="utf-8")
