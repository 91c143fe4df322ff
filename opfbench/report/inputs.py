"""Read the files a run, a forecast run and a fault study wrote (see the file contracts:
run folder, forecast folder, fault folder). Every input is optional: a missing one is
None plus the command that produces it, so its report section can say so."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

import opfbench
from opfbench.registry import FORMULATIONS
from opfbench.report.tables import REFERENCE_NIGHT

RUN_COMMAND = "opfbench run --out {dir}"
DETAIL_COMMAND = "opfbench run --detail --out {dir} (default on for periods of ≤ 2 days)"
FORECAST_COMMAND = "opfbench forecast --dataset pv --out DIR and opfbench forecast --dataset wind --out DIR"
FAULT_COMMAND = "opfbench fault CASE --out DIR (then opfbench report RUN_DIR --fault-dir DIR)"
YEAR_COMMAND = "opfbench run --period year --out reports/year (then opfbench report RUN_DIR --year-dir reports/year)"
DOCS_FORECAST = Path(opfbench.__file__).resolve().parents[1] / "docs" / "forecast"
"""The committed forecast JSONs, read when no forecast folder is given (a source checkout only)."""
DOCS_YEAR = Path(opfbench.__file__).resolve().parents[1] / "docs" / "year"
"""The committed year run's summary and manifest, read when no year folder is given."""


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
    missing: dict[str, str] = field(default_factory=dict)  # input name -> how to produce it


def _json(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.is_file() else None


TRACE_BUS = 27  # the fault traces plotted: at the paper's DFIG
STEP_COLUMNS = (
    "case",
    "strategy",
    "k",
    "night_mode",
    "forecast",
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
)
"""The columns of steps.parquet the report uses."""


def reference_setting(summary: pd.DataFrame) -> tuple[str, float] | None:
    """(night mode, k) of the report's per-step plots: night connected (else the first
    mode), forecast off, the smallest k; None without a forecast-off row."""
    modes = list(dict.fromkeys(summary["night_mode"]))
    mode = REFERENCE_NIGHT if REFERENCE_NIGHT in modes else modes[0]
    off = summary[(summary["night_mode"] == mode) & (summary["forecast"] == "off")]
    return (mode, float(off["k"].min())) if len(off) else None


def _filtered(path: Path, columns: tuple[str, ...] | None, filters: list | None) -> pd.DataFrame | None:
    """The rows of a run table matching `filters` (parquet filters: a year's table need not
    fit in memory) with only `columns` (those present; None: all), text as arrow strings;
    None when the file is absent or no row matches."""
    if not path.is_file():
        return None
    schema = pq.read_schema(path)
    wanted = [c for c in schema.names if columns is None or c in columns]
    # text read dictionary-encoded (filtering a fault study's million trace rows is several
    # times faster on the codes), decoded once filtered
    text = [f.name for f in schema if f.name in wanted and pa.types.is_string(f.type)]
    table = pq.read_table(path, columns=wanted, filters=filters, read_dictionary=text)
    table = table.cast(
        pa.schema([pa.field(f.name, pa.string()) if f.name in text else f for f in table.schema], metadata=table.schema.metadata)
    )
    frame = table.to_pandas(types_mapper={pa.string(): pd.StringDtype("pyarrow")}.get)
    return frame if len(frame) else None


def _reference_filter(summary: pd.DataFrame | None) -> list | None:
    """Parquet filter for the rows of the reference setting (`reference_setting`)."""
    reference = reference_setting(summary) if summary is not None else None
    if reference is None:
        return None
    return [("night_mode", "==", reference[0]), ("forecast", "==", "off"), ("k", "==", reference[1])]


def _steps(path: Path, summary: pd.DataFrame | None) -> pd.DataFrame | None:
    """The per-step rows the report uses — every formulation's (convergence tables) and the
    reference setting's (plots) — with only the columns it uses."""
    reference = _reference_filter(summary)
    filters = None if reference is None else [[("strategy", "in", list(FORMULATIONS))], reference]
    return _filtered(path, STEP_COLUMNS, filters)


def _summary(path: Path) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    summary = pd.read_csv(path, dtype={"case": str, "strategy": str, "night_mode": str, "forecast": str})
    return summary if len(summary) else None


def load_inputs(
    run_dir: str | Path,
    forecast_dir: str | Path | None = None,
    fault_dir: str | Path | None = None,
    year_dir: str | Path | None = None,
) -> Inputs:
    """Read what exists; record how to produce what does not."""
    run = Path(run_dir)
    inp = Inputs(run_dir=run)
    inp.manifest = _json(run / "manifest.json")
    inp.summary = _summary(run / "summary.csv")
    inp.steps = _steps(run / "steps.parquet", inp.summary)
    inp.der_q = _filtered(run / "der_q.parquet", None, _reference_filter(inp.summary))  # plotted: the reference rows
    for name, frame in (("manifest.json", inp.manifest), ("steps.parquet", inp.steps), ("summary.csv", inp.summary)):
        if frame is None:
            inp.missing[name] = RUN_COMMAND.format(dir=run)
    if inp.der_q is None:  # the report plots the DER setpoints (the per-bus |V| table it does not read)
        inp.missing["der_q.parquet"] = DETAIL_COMMAND.format(dir=run)

    inp.forecast_dir = Path(forecast_dir) if forecast_dir is not None else DOCS_FORECAST
    for dataset in ("pv", "wind"):
        data = _json(inp.forecast_dir / f"forecast_{dataset}.json")
        if data is not None:
            inp.forecast[dataset] = data
    if not inp.forecast:
        inp.missing["forecast"] = FORECAST_COMMAND

    if fault_dir is not None:
        inp.fault_dir = Path(fault_dir)
        inp.fault = _filtered(inp.fault_dir / "fault.parquet", None, None)
        inp.traces = _filtered(
            inp.fault_dir / "traces.parquet",
            None,  # plotted: one bus, forecast off
            [("bus", "==", TRACE_BUS), ("forecast", "==", "off")],
        )
        inp.fault_manifest = _json(inp.fault_dir / "manifest.json")
    if inp.fault is None:
        inp.missing["fault.parquet"] = FAULT_COMMAND
    if inp.traces is None:
        inp.missing["traces.parquet"] = FAULT_COMMAND

    inp.year_dir = Path(year_dir) if year_dir is not None else DOCS_YEAR
    inp.year_summary = _summary(inp.year_dir / "summary.csv")
    inp.year_manifest = _json(inp.year_dir / "manifest.json")
    if inp.year_summary is None or inp.year_manifest is None:
        inp.missing["year run"] = YEAR_COMMAND
    return inp
