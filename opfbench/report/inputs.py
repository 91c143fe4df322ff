"""Read the files a run, a forecast run and a fault study wrote (docs/CONTRACTS.md: run
folder, forecast folder, fault folder). Every input is optional: a missing one is
None plus the command that produces it, so its report section can say so. A damaged
one — not UTF-8, not JSON, not an object, a JSON name given twice, a truncated or empty
parquet file, a folder where the file belongs, a column missing or of the wrong kind, a
number outside its domain (±inf, a k outside [0, 1]), a manifest field of the wrong kind
or an unknown schema version — is an `InputError` naming the file and what is wrong,
before anything is drawn."""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

import opfbench
from opfbench.errors import InputError
from opfbench.io.spec import parse_spec
from opfbench.report.sources import check_given, report_sources
from opfbench.report.tables import REFERENCE_NIGHT, Kinds
from opfbench.schema import DER_Q, FAULT, FRONTIER_SUMMARY, KEYS, STEPS, SUMMARY, TRACES, Table
from opfbench.study.store import SCHEMA

RUN_COMMAND = "opfbench run --out {dir}"
DETAIL_COMMAND = "opfbench run --detail --out {dir} (default on for periods of ≤ 2 days)"
FORECAST_COMMAND = "opfbench forecast --dataset pv --out DIR and opfbench forecast --dataset wind --out DIR"
FAULT_COMMAND = "opfbench fault CASE --out DIR (then opfbench report RUN_DIR --fault-dir DIR)"
YEAR_COMMAND = "opfbench run --period year --out reports/year (then opfbench report RUN_DIR --year-dir reports/year)"
DOCS_FORECAST = Path(opfbench.__file__).resolve().parents[1] / "docs" / "forecast"
"""The committed forecast JSONs, read when no forecast folder is given (a source checkout only)."""
DOCS_YEAR = Path(opfbench.__file__).resolve().parents[1] / "docs" / "year"
"""The committed year run's summary and manifest, read when no year folder is given."""
DOCS_LEARNED = Path(opfbench.__file__).resolve().parents[1] / "docs" / "learned"
"""The committed learned-rule studies (one run folder each: summary, training summary, fits),
shown by the headline section when the run itself trained no learned rule."""
DOCS_FIELD_YEAR = Path(opfbench.__file__).resolve().parents[1] / "docs" / "field-year"
"""The committed year on real grids (SimBench 1-MV-rural and 1-LV-rural3): summary and manifest."""
FIELD_YEAR_COMMAND = (
    "opfbench run --case simbench:1-MV-rural--0-sw simbench:1-LV-rural3--0-sw --k 0 0.4 "
    "--night-modes connected disconnected --period year --out docs/field-year"
)


@dataclass
class Inputs:
    """Everything the report reads; None where the file is absent (see `missing`)."""

    run_dir: Path
    manifest: dict | None = None
    steps: pd.DataFrame | None = None
    summary: pd.DataFrame | None = None
    der_q: pd.DataFrame | None = None
    forecast: dict[str, dict] = field(default_factory=dict)  # dataset -> forecast_<dataset>.json
    forecast_dir: Path | None = None
    fault: pd.DataFrame | None = None
    traces: pd.DataFrame | None = None
    fault_manifest: dict | None = None
    fault_dir: Path | None = None
    year_summary: pd.DataFrame | None = None
    year_manifest: dict | None = None
    year_dir: Path | None = None
    field_summary: pd.DataFrame | None = None  # the committed year on real grids (docs/field-year)
    field_manifest: dict | None = None
    field_frontier: pd.DataFrame | None = None
    frontier: pd.DataFrame | None = None  # frontier.csv: losses against compliance (a run before it has none)
    train_summary: pd.DataFrame | None = None  # train/summary.csv: the rules over the training period
    learned: dict[str, dict] = field(default_factory=dict)  # the run's learned/<file>.json -> what it holds (a row)
    studies: list[Inputs] = field(default_factory=list)  # committed learned-rule studies (docs/learned), if the run trained none
    missing: dict[str, str] = field(default_factory=dict)  # input name -> how to produce it

    def kinds(self) -> Kinds:
        """How the run's configurations are classified: as its manifest records them
        (`report.tables.Kinds`)."""
        labels = self.summary["strategy"] if self.summary is not None else ()
        return Kinds.of(labels, (self.manifest or {}).get("strategies"))

    def models(self) -> dict[str, str]:
        """Each case of the run → the case it is modelled by (its spec without `line-z`),
        whose rows the training summary holds."""
        out = {}
        for case in set(self.summary["case"].astype(str)) if self.summary is not None else ():
            try:
                out[case] = parse_spec(case).model.text
            except InputError:
                out[case] = case
        return out


TEXT, NUMBER, TIME, FLAG, NULL = "text", "number", "time", "true/false", "null"
"""Kinds of column a report input must have (`_kind`)."""
_KIND = {"text": TEXT, "number": NUMBER, "integer": NUMBER, "time": TIME, "true/false": FLAG}


def _kinds(table: Table, names: tuple[str, ...]) -> dict[str, str]:
    """The kinds the report checks of the columns `names` of a declared table (`opfbench.schema`)."""
    return {name: _KIND[table[name].dtype] for name in names}


_KEYS = _kinds(STEPS, tuple(KEYS))
STEP_KINDS = _kinds(
    STEPS,
    (
        *KEYS,
        "time",
        "status",
        "losses_kw",
        "vmin_pu",
        "vmax_pu",
        "solver_ms",
        "iterations",
        "certified_by",
        "fallback",
        "solver_status",
        "lower_bound_kw",
    ),
)
"""The columns of steps.parquet the report uses, and their kinds."""
STEP_COLUMNS = tuple(STEP_KINDS)
STEP_OPTIONAL = _kinds(STEPS, ("vm_error_pu",))
"""Columns of steps.parquet the report uses where present (a folder written before they were declared lacks them)."""
DER_Q_KINDS = _kinds(DER_Q, (*KEYS, "time", "bus", "kind", "q_mvar"))
_FAULT_KEYS = _kinds(FAULT, ("case", "fault_bus", "strategy", "k", "forecast", "variant"))
FAULT_KINDS = _FAULT_KEYS | _kinds(FAULT, ("bus", "recovery_ms", "status", "vmin_pu", "margin_pu", "faulted"))
TRACE_KINDS = _FAULT_KEYS | _kinds(TRACES, ("bus", "t_s", "v_pu", "q_mvar"))
SUMMARY_NUMBERS = (
    "steps",
    "hours",
    "avg_loss_kw",
    "energy_kwh",
    "no_action_kwh",
    "savings_pct",
    "not_ok_steps",
    "voltage_violation_steps",
    "vmin_pu",
    "vmax_pu",
    "max_excursion_mvar",
    "excursion_steps",
    "lower_bound_kwh",
    "gap_kwh",
    "gap_pct",
    "wall_s",
    "solver_s",
    "certified_share",
)
"""The numeric columns of summary.csv the report uses besides its keys (`_KEYS`);
pf_converged_steps, pf_diverged_steps and rule_non_finite_steps when present."""
FORECAST_METRICS = ("mse_scaled", "mape_pct", "mae_kw", "rmse_kw", "skill", "fit_s")
"""The metrics of a forecast JSON the report shows."""
SUMMARY_COUNTS = tuple(c.name for c in SUMMARY if c.dtype == "integer")
"""Columns of summary.csv that count steps: whole numbers ≥ 0."""
SUMMARY_OPTIONAL_NUMBERS = (
    "pf_converged_steps",
    "pf_diverged_steps",
    "rule_non_finite_steps",
    "curtailed_kwh",
    "cost_kwh",
    "frontier_kwh",
    "frontier_bound_kwh",
    "gap_eq_kwh",
    "gap_eq_pct",
    "share_eq_pct",
    "share_pct",
    "frontier_missing_steps",
    "below_frontier_steps",
)
"""Columns of summary.csv a run writes that an older one may lack (checked where present)."""
FRONTIER_KINDS = _kinds(FRONTIER_SUMMARY, tuple(FRONTIER_SUMMARY.names))
"""frontier.csv's columns the report uses."""


def _number(value: object) -> bool:
    """A finite JSON number (true/false is none; NaN and Infinity are not JSON)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _label(value: object) -> bool:
    return isinstance(value, str) and bool(value.strip()) and value.isprintable()


_JSON_KINDS = {
    "a list": lambda v: isinstance(v, list),
    "a list of text": lambda v: isinstance(v, list) and all(isinstance(i, str) for i in v),
    "a list of numbers in [0, 1]": lambda v: isinstance(v, list) and all(_number(i) and 0 <= i <= 1 for i in v),
    "an object": lambda v: isinstance(v, dict),
    "text": lambda v: isinstance(v, str),
    "a printable label": _label,
    "a number": _number,
    "a number > 0": lambda v: _number(v) and v > 0,
    "a finite number ≥ 0": lambda v: _number(v) and v >= 0,
    "a whole number ≥ 0": lambda v: _number(v) and isinstance(v, int) and v >= 0,
    "true or false": lambda v: isinstance(v, bool),
    "a strategy kind": lambda v: v in ("local", "formulation"),
    "a model role": lambda v: v in ("exact", "relaxation", "approximation"),
}
"""JSON kinds (with their domain) of the manifest fields the report reads."""
MANIFEST_FIELDS = {
    "command": "a list",
    "config": "an object",
    "period": "an object",
    "data_sources": "a list",
    "versions": "an object",
    "machine": "an object",
    "cases": "an object",
    "tasks": "a list",
    "timings": "an object",
    "strategies": "an object",
    "config.cases": "a list of text",
    "config.strategies": "a list of text",
    "config.ks": "a list of numbers in [0, 1]",
    "config.night_modes": "a list of text",
    "config.forecast": "a list of text",
    "config.night": "text",
    "config.period": "text",
    "config.step_minutes": "a number > 0",
    "config.acopf_solver": "text",
    "config.price_per_kwh": "a finite number ≥ 0",
    "config.currency": "a printable label",
    "config.price_source": "text",
    "timings.wall_s": "a finite number ≥ 0",
    "timings.workers": "a whole number ≥ 0",
    "timings.peak_rss_mb": "a finite number ≥ 0",
    "timings.worker_peak_rss_mb": "a finite number ≥ 0",
}
"""The manifest fields the report reads and their JSON kinds (null allowed; a field may be
absent, except `MANIFEST_REQUIRED`)."""
MANIFEST_REQUIRED = ("config", "config.period")
"""What every run's manifest holds (a fault study's manifest has a config, but no period)."""


CASE_FIELDS = {"buses": "a whole number ≥ 0", "ders": "a list", "vmin_pu": "a number", "vmax_pu": "a number"}
"""The fields of a manifest's cases.<name> the report reads, and their JSON types."""
STRATEGY_FIELDS = {"kind": "a strategy kind", "uses_forecast": "true or false", "role": "a model role"}
"""The fields of a manifest's strategies.<label> the report reads (a kind required), and their JSON types."""


def _is_kind(value: object, expected: str) -> bool:
    """`value` is of the JSON kind `expected` (a key of `_JSON_KINDS`)."""
    return bool(_JSON_KINDS[expected](value))


def _damaged(path: Path, problem: str, command: str) -> InputError:
    return InputError(f"{path}: {problem}; rebuild it with `{command}`")


def _present(path: Path, command: str) -> bool:
    """Whether the input `path` exists — as a file: a folder (or anything else) in its
    place is damage, not absence."""
    if not path.exists():
        return False
    if not path.is_file():
        raise _damaged(path, "is not a file (a folder?)", command)
    return True


def _unique_keys(pairs: list[tuple[str, object]]) -> dict:
    """A JSON object's members; a name given twice is refused (JSON readers disagree on
    which value wins)."""
    out = dict(pairs)
    if len(out) < len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))  # type: ignore[func-returns-value]
        raise ValueError(f"the name {twice!r} appears twice in one object")
    return out


def _json(path: Path, command: str) -> dict | None:
    """The JSON object in `path`, None when the file is absent."""
    if not _present(path, command):
        return None
    try:
        data = json.loads(path.read_bytes().decode("utf-8"), object_pairs_hook=_unique_keys)
    except OSError as exc:
        raise InputError(f"{path}: cannot read it ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise _damaged(path, f"not a UTF-8 text file (byte {exc.start})", command) from None
    except ValueError as exc:
        raise _damaged(path, f"not valid JSON ({exc})", command) from None
    except RecursionError:
        raise _damaged(path, "not a run's JSON (nested too deeply to read)", command) from None
    if not isinstance(data, dict):
        raise _damaged(path, f"holds a JSON {type(data).__name__}, not an object", command)
    return data


def _manifest(path: Path, command: str) -> dict | None:
    """A run manifest: a JSON object of a schema this version reads, whose fields the
    report uses have their types (`MANIFEST_FIELDS`)."""
    m = _json(path, command)
    if m is None:
        return None
    schema = m.get("schema")
    if isinstance(schema, bool) or not isinstance(schema, int) or not 1 <= schema <= SCHEMA:
        raise _damaged(path, f"schema {schema!r} is not one this opfbench reads (1..{SCHEMA}; a newer one wrote it?)", command)
    for key, expected in MANIFEST_FIELDS.items():
        *parents, name = key.split(".")
        node: object = m
        for parent in parents:
            node = node.get(parent) if isinstance(node, dict) else None
        value = node.get(name) if isinstance(node, dict) else None
        if value is None and key in MANIFEST_REQUIRED:
            raise _damaged(path, f"no {key}: not the manifest of a run", command)
        if value is not None and not _is_kind(value, expected):
            raise _damaged(path, f"{key} is {value!r}, expected {expected}", command)
    for case, info in (m.get("cases") or {}).items():
        fields: list[tuple[str, object, str]] = [(f"cases.{case}", info, "an object")]
        if isinstance(info, dict):
            fields += [(f"cases.{case}.{k}", info.get(k), kind) for k, kind in CASE_FIELDS.items()]
            ders = info["ders"] if isinstance(info.get("ders"), list) else []
            fields += [(f"cases.{case}.ders[{i}]", d, "an object") for i, d in enumerate(ders)]
        for key, value, expected in fields:
            if value is not None and not _is_kind(value, expected):
                raise _damaged(path, f"{key} is {value!r}, expected {expected}", command)
    for label, record in (m.get("strategies") or {}).items():
        if not isinstance(record, dict) or "kind" not in record:
            raise _damaged(path, f"strategies.{label} is {record!r}, expected an object with a kind", command)
        for name, expected in STRATEGY_FIELDS.items():
            if record.get(name) is not None and not _is_kind(record[name], expected):
                raise _damaged(path, f"strategies.{label}.{name} is {record[name]!r}, expected {expected}", command)
    return m


def _kind(t: pa.DataType) -> str:
    if pa.types.is_dictionary(t):
        t = t.value_type
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return TEXT
    if pa.types.is_boolean(t):
        return FLAG
    if pa.types.is_integer(t) or pa.types.is_floating(t):
        return NUMBER
    if pa.types.is_null(t):
        return NULL
    if pa.types.is_timestamp(t):
        return TIME if t.tz is not None else "time without a time zone"
    return str(t)


TRACE_BUS = 27  # the fault traces plotted: at the paper's DFIG


def reference_setting(summary: pd.DataFrame) -> tuple[str, float] | None:
    """(night mode, k) of the report's per-step plots: night connected (else the first
    mode), forecast off, the smallest k; None without a forecast-off row."""
    modes = list(dict.fromkeys(summary["night_mode"]))
    mode = REFERENCE_NIGHT if REFERENCE_NIGHT in modes else modes[0]
    off = summary[(summary["night_mode"] == mode) & (summary["forecast"] == "off")]
    return (mode, float(off["k"].min())) if len(off) else None


def _filtered(
    path: Path,
    kinds: dict[str, str],
    filters: list | None,
    command: str,
    every_column: bool = False,
    keys: tuple[str, ...] = tuple(_KEYS),
    optional: dict[str, str] | None = None,
) -> pd.DataFrame | None:
    """The rows of a run table matching `filters` (parquet filters: a year's table need not
    fit in memory) with the columns of `kinds` (every column with `every_column`), text as
    arrow strings; None when the file is absent, holds no row or no row matches.
    InputError when it is not a readable parquet file, lacks a column of `kinds` or has it
    of another kind, or a row read has no value in one of the `keys` columns, or a number
    read is outside its domain (`_check_numbers`). The `optional` columns are read, and
    checked, where the file has them."""
    if not _present(path, command):
        return None
    try:
        if pq.ParquetFile(path).metadata.num_rows == 0:
            return None
        schema = pq.read_schema(path)
        kinds = kinds | {name: kind for name, kind in (optional or {}).items() if name in schema.names}
        for name, kind in kinds.items():
            found = _kind(schema.field(name).type) if name in schema.names else None
            if found != kind and found != NULL:  # a column of nulls only (no row has a value) is any kind
                raise _damaged(path, f"column {name!r} {'is ' + found if found else 'is missing'}, expected {kind}", command)
        wanted = [c for c in schema.names if every_column or c in kinds]
        # text read dictionary-encoded (filtering a fault study's million trace rows is several
        # times faster on the codes), decoded once filtered
        text = [f.name for f in schema if f.name in wanted and pa.types.is_string(f.type)]
        table = pq.read_table(path, columns=wanted, filters=filters, read_dictionary=text)
    except (OSError, pa.ArrowException) as exc:
        raise _damaged(path, f"not a readable parquet file ({exc})", command) from None
    for key in keys:
        if table.column(key).null_count:
            raise _damaged(path, f"{table.column(key).null_count} row(s) have no {key}", command)
    _check_numbers(path, {name: table.column(name).to_numpy(zero_copy_only=False) for name, kind in kinds.items()
                          if kind == NUMBER and name in table.column_names}, command)  # fmt: skip
    table = table.cast(
        pa.schema([pa.field(f.name, pa.string()) if f.name in text else f for f in table.schema], metadata=table.schema.metadata)
    )
    frame = table.to_pandas(types_mapper={pa.string(): pd.StringDtype("pyarrow")}.get)
    return frame if len(frame) else None


DOMAINS = {"k": (0.0, 1.0)}
"""Columns whose numbers have a domain narrower than finite (k: a reserve coefficient)."""


def _check_numbers(path: Path, columns: dict[str, np.ndarray], command: str) -> None:
    """Numbers a report shows are finite (NaN is "no figure", ±inf is damage) and inside
    their `DOMAINS`."""
    for name, values in columns.items():
        values = np.asarray(values, dtype=float)
        low, high = DOMAINS.get(name, (-np.inf, np.inf))
        bad = np.isinf(values) | (values < low) | (values > high)
        if bad.any():
            where = f" outside [{low:g}, {high:g}]" if name in DOMAINS else ""
            raise _damaged(path, f"column {name!r} holds {values[bad][0]:g}{where} ({int(bad.sum())} row(s))", command)


def _reference_filter(summary: pd.DataFrame | None) -> list | None:
    """Parquet filter for the rows of the reference setting (`reference_setting`)."""
    reference = reference_setting(summary) if summary is not None else None
    if reference is None:
        return None
    return [("night_mode", "==", reference[0]), ("forecast", "==", "off"), ("k", "==", reference[1])]


def _steps(path: Path, summary: pd.DataFrame | None, kinds: Kinds, command: str) -> pd.DataFrame | None:
    """The per-step rows the report uses — every formulation's (convergence tables) and the
    reference setting's (plots) — with only the columns it uses."""
    reference = _reference_filter(summary)
    keys = (*_KEYS, "time", "status")
    if reference is None or summary is None:
        return _filtered(path, STEP_KINDS, None, command, keys=keys, optional=STEP_OPTIONAL)
    formulations = sorted(kinds.formulations)
    filters = [[("strategy", "in", formulations)], reference] if formulations else [reference]
    return _filtered(path, STEP_KINDS, filters, command, keys=keys, optional=STEP_OPTIONAL)


def _summary(path: Path, command: str) -> pd.DataFrame | None:
    """summary.csv (None when absent or without rows); InputError unless UTF-8 CSV text
    with the columns the report uses, numbers where numbers belong (finite, within
    `DOMAINS`)."""
    if not _present(path, command):
        return None
    keys = {"case": str, "strategy": str, "night_mode": str, "forecast": str}
    summary = _csv(path, command, keys)
    missing = [c for c in (*_KEYS, *SUMMARY_NUMBERS) if c not in summary.columns]
    if missing:
        raise _damaged(path, f"no column {', '.join(missing)}", command)
    if summary.empty:
        return None
    for name in ("k", *SUMMARY_NUMBERS, *(c for c in SUMMARY_OPTIONAL_NUMBERS if c in summary.columns)):
        column = summary[name]
        if not pd.api.types.is_numeric_dtype(column) or pd.api.types.is_bool_dtype(column):
            bad = next((v for v in column if not _is_number(v)), column.iloc[0])
            raise _damaged(path, f"column {name!r} holds {bad!r}, not a number", command)
        _check_numbers(path, {name: column.to_numpy()}, command)
        if name in SUMMARY_COUNTS and not ((column >= 0) & (column == np.round(column))).all():
            bad = column[~((column >= 0) & (column == np.round(column)))].iloc[0]
            raise _damaged(path, f"column {name!r} holds {bad:g}, not a count of steps", command)
    for key in _KEYS:
        if summary[key].isna().any():
            raise _damaged(path, f"{int(summary[key].isna().sum())} row(s) have no {key}", command)
    repeated = summary.duplicated(list(_KEYS))
    if repeated.any():
        row = summary[repeated].iloc[0]
        raise _damaged(path, "configuration " + ", ".join(f"{k}={row[k]}" for k in _KEYS) + " has more than one row", command)
    return summary


def _csv(path: Path, command: str, text_columns: dict[str, type[str]]) -> pd.DataFrame:
    """A CSV table (numbers read exactly as written); InputError naming the file unless it
    is readable UTF-8 CSV text."""
    try:
        text = path.read_bytes().decode("utf-8")
        return pd.read_csv(io.StringIO(text), dtype=text_columns, float_precision="round_trip")
    except OSError as exc:
        raise InputError(f"{path}: cannot read it ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise _damaged(path, f"not a UTF-8 text file (byte {exc.start})", command) from None
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise _damaged(path, f"not a readable CSV table ({exc})", command) from None


def _frontier(path: Path, command: str) -> pd.DataFrame | None:
    """frontier.csv (None when absent: a run written before the frontier); InputError unless
    UTF-8 CSV text with the columns the report uses, numbers where numbers belong (ε may
    be inf: the physical limits alone)."""
    if not path.is_file():
        return None
    frame = _csv(path, command, {"case": str, "night_mode": str})
    missing = [c for c in FRONTIER_KINDS if c not in frame.columns]
    if missing:
        raise _damaged(path, f"no column {', '.join(missing)}", command)
    if frame.empty:  # no optimum ran (a three-phase feeder's run)
        return None
    for name, kind in FRONTIER_KINDS.items():
        if kind == NUMBER and (not pd.api.types.is_numeric_dtype(frame[name]) or pd.api.types.is_bool_dtype(frame[name])):
            raise _damaged(path, f"column {name!r} holds a value that is not a number", command)
        if kind == FLAG and not pd.api.types.is_bool_dtype(frame[name]):
            raise _damaged(path, f"column {name!r} holds a value that is not true or false", command)
    eps = frame["eps_pu"].to_numpy(dtype=float)
    if np.isnan(eps).any() or (eps < 0).any():
        raise _damaged(path, "column 'eps_pu' holds a value that is not a widening ≥ 0", command)
    _check_numbers(
        path, {c: frame[c].to_numpy() for c, kind in FRONTIER_KINDS.items() if kind == NUMBER and c != "eps_pu"}, command
    )
    return frame if not frame.empty else None


def _is_number(value: object) -> bool:
    try:
        float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return True


def _forecast_json(path: Path, command: str) -> dict | None:
    """A forecast run's metrics JSON: an object whose "metrics" maps each model to an
    object whose `FORECAST_METRICS` are numbers (or null)."""
    data = _json(path, command)
    if data is None:
        return None
    metrics = data.get("metrics")
    if not isinstance(metrics, dict):
        raise _damaged(path, f"metrics is {metrics!r}, expected an object of models", command)
    for model, values in metrics.items():
        if not isinstance(values, dict):
            raise _damaged(path, f"metrics[{model!r}] is {values!r}, expected an object of numbers", command)
        for key in FORECAST_METRICS:
            value = values.get(key)
            if value is not None and not _number(value):
                raise _damaged(path, f"metrics[{model!r}][{key!r}] is {value!r}, expected a finite number", command)
    return data


def load_inputs(
    run_dir: str | Path,
    forecast_dir: str | Path | None = None,
    fault_dir: str | Path | None = None,
    year_dir: str | Path | None = None,
) -> Inputs:
    """Read what exists; record how to produce what does not; InputError for what is damaged."""
    run = Path(run_dir)
    inp = Inputs(run_dir=run)
    command = RUN_COMMAND.format(dir=run)
    inp.manifest = _manifest(run / "manifest.json", command)
    inp.summary = _summary(run / "summary.csv", command)
    inp.frontier = _frontier(run / "frontier.csv", command)
    inp.steps = _steps(run / "steps.parquet", inp.summary, inp.kinds(), command)
    # plotted: the reference rows
    inp.der_q = _filtered(
        run / "der_q.parquet", DER_Q_KINDS, _reference_filter(inp.summary), command, True, (*_KEYS, "time", "bus")
    )
    for name, frame in (("manifest.json", inp.manifest), ("steps.parquet", inp.steps), ("summary.csv", inp.summary)):
        if frame is None:
            inp.missing[name] = command
    if inp.der_q is None:  # the report plots the DER setpoints (the per-bus |V| table it does not read)
        inp.missing["der_q.parquet"] = DETAIL_COMMAND.format(dir=run)
    _load_training(inp, command)
    if inp.train_summary is None:
        inp.studies = [load_study(folder) for folder in sorted(DOCS_LEARNED.glob("*/")) if (folder / "summary.csv").is_file()]
    _load_sources(inp, forecast_dir, fault_dir, year_dir)
    return inp


def _load_training(inp: Inputs, command: str) -> None:
    """A run's training summary and one line per fitted rule of its own (learned/)."""
    inp.train_summary = _summary(inp.run_dir / "train" / "summary.csv", command)
    fitted = (inp.manifest or {}).get("config", {}).get("fitted") or []
    for ref in sorted({str(f.get("ref")) for f in fitted if isinstance(f, dict)}):
        if ref.startswith("learned/"):  # the run's own fits (a params= file given lies elsewhere)
            inp.learned[ref] = _learned_row(inp.run_dir / ref, command)


def load_study(folder: Path) -> Inputs:
    """A finished learned-rule study's summaries, manifest and fits (no per-step tables)."""
    command = RUN_COMMAND.format(dir=folder)
    inp = Inputs(run_dir=folder, manifest=_manifest(folder / "manifest.json", command))
    inp.summary = _summary(folder / "summary.csv", command)
    inp.frontier = _frontier(folder / "frontier.csv", command)
    _load_training(inp, command)
    return inp


def _learned_row(path: Path, command: str) -> dict:
    """A fitted rule's parameters file (`learned.rules.LearnedParams`) as a table row."""
    data = _json(path, command) or {}
    try:
        train, fit = data["train"], data.get("fit") or {}
        return {
            "family": str(data["family"]),
            "fitted on": str(data["case"]),
            "training period": str(train["period"]),
            "certified optimal steps": int(train["optimal_steps"]),
            "DER": len(data["ders"]),
            "slope bound ρ": float(data["rho"]),
            "contraction factor": float(fit.get("contraction_factor", float("nan"))),
            "training data sha256": f"{str(data['data_sha256'])[:12]}…",
        }
    except (KeyError, TypeError, ValueError) as exc:
        raise _damaged(path, f"not a fitted rule's parameters ({type(exc).__name__}: {exc})", command) from None


def _load_sources(
    inp: Inputs, forecast_dir: str | Path | None, fault_dir: str | Path | None, year_dir: str | Path | None
) -> None:
    """The forecast, fault and year-run inputs into `inp`."""
    inp.forecast_dir = Path(forecast_dir) if forecast_dir is not None else DOCS_FORECAST
    for dataset in ("pv", "wind"):
        path = inp.forecast_dir / f"forecast_{dataset}.json"
        data = _forecast_json(path, f"opfbench forecast --dataset {dataset} --out {inp.forecast_dir}")
        if data is not None:
            inp.forecast[dataset] = data
    if not inp.forecast:
        inp.missing["forecast"] = FORECAST_COMMAND

    if fault_dir is not None:
        inp.fault_dir = Path(fault_dir)
        fault_keys = (*_FAULT_KEYS, "bus")
        inp.fault = _filtered(inp.fault_dir / "fault.parquet", FAULT_KINDS, None, FAULT_COMMAND, True, fault_keys)
        inp.traces = _filtered(
            inp.fault_dir / "traces.parquet",
            TRACE_KINDS,
            [("bus", "==", TRACE_BUS), ("forecast", "==", "off")],  # plotted: one bus, forecast off
            FAULT_COMMAND,
            True,
            fault_keys,
        )
        inp.fault_manifest = _json(inp.fault_dir / "manifest.json", FAULT_COMMAND)
    if inp.fault is None:
        inp.missing["fault.parquet"] = FAULT_COMMAND
    if inp.traces is None:
        inp.missing["traces.parquet"] = FAULT_COMMAND

    inp.year_dir = Path(year_dir) if year_dir is not None else DOCS_YEAR
    inp.year_summary = _summary(inp.year_dir / "summary.csv", YEAR_COMMAND)
    inp.year_manifest = _manifest(inp.year_dir / "manifest.json", YEAR_COMMAND)
    if inp.year_summary is None or inp.year_manifest is None:
        inp.missing["year run"] = YEAR_COMMAND
    inp.field_summary = _summary(DOCS_FIELD_YEAR / "summary.csv", FIELD_YEAR_COMMAND)
    inp.field_manifest = _manifest(DOCS_FIELD_YEAR / "manifest.json", FIELD_YEAR_COMMAND)
    inp.field_frontier = _frontier(DOCS_FIELD_YEAR / "frontier.csv", FIELD_YEAR_COMMAND)
    if inp.field_summary is None or inp.field_manifest is None:
        inp.missing["real grids' year run"] = FIELD_YEAR_COMMAND


def checked_sources(
    forecast_dir: Path | None, fault_dir: Path | None, year_dir: Path | None
) -> tuple[Path | None, Path | None, Path | None]:
    """The forecast, fault and year-run folders the report reads (`report_sources`), after
    checking that each one given holds what it is for (`check_given`) and reading every
    one's files (InputError naming a damaged one) — what `opfbench run` does before its
    work and `opfbench report` before drawing."""
    check_given(forecast_dir, fault_dir, year_dir)
    sources = report_sources(forecast_dir, fault_dir, year_dir)
    _load_sources(Inputs(run_dir=Path()), *sources)
    return sources
