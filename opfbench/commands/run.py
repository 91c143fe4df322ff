"""`opfbench run`: the study — every case × strategy × k × night mode × forecast over a
period — split into tasks, run on every core (Dask) or a Dask cluster, resumable, writing
the run folder (manifest, tasks/, steps.parquet, summary.csv; docs/CONTRACTS.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from opfbench.capability import PAPER_KS
from opfbench.commands.arguments import (
    STRATEGY_HELP,
    add_case_options,
    add_execution_options,
    add_plugin_option,
    case_spec,
    fraction,
    path,
    strategy_labels,
)
from opfbench.formulations.acopf_options import ACOPF_SOLVERS
from opfbench.io.sources import formats
from opfbench.jsonio import print_json
from opfbench.registry.references import DEFAULT_FORECAST, DEFAULT_RUN
from opfbench.study.config import CHUNKS, DEFAULT_NIGHT, NIGHT_MODES, StudyConfig
from opfbench.study.price import DEFAULT_CURRENCY, DEFAULT_PRICE_PER_KWH, DEFAULT_PRICE_SOURCE

if TYPE_CHECKING:
    from opfbench.study.run_family import StudyRun

SUITES = ("simbench",)


def suite_cases(suite: str | None) -> list[str]:
    """The case specs of a field suite (none for None)."""
    if suite is None:
        return []
    from opfbench.io.simbench import SUITE

    return [f"simbench:{code}" for code in SUITE]


def _minutes(text: str) -> float:
    value = fraction(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the study (default: the paper day on paper33, every strategy)")
    cases = p.add_mutually_exclusive_group()
    cases.add_argument(
        "--case",
        nargs="+",
        default=None,
        help=f"case specs (default paper33), each {formats()}; e.g. paper33 case69-der simbench:1-MV-rural--0-sw",
    )
    cases.add_argument(
        "--suite",
        choices=SUITES,
        default=None,
        help="a field suite instead of --case: simbench = every SimBench LV and MV grid of scenario 0, switch "
        "variant sw, on its own profiles (the report checks the ranking claim per grid)",
    )
    add_case_options(p)
    p.add_argument(
        "--strategies",
        nargs="+",
        default=None,
        metavar="LABEL",
        help=STRATEGY_HELP + "; default: every built-in one",
    )
    p.add_argument(
        "--forecast-strategies",
        nargs="+",
        default=None,
        metavar="LABEL",
        help="which of the strategies run under the forecast sources other than off (only those that read a forecast "
        "do), or 'all'; default: with the default --strategies the paper's Algorithm 3 rules "
        f"({' '.join(DEFAULT_FORECAST)}: the grid codes' rules know no forecast, only Algorithm 3's limit would "
        "change), else all",
    )
    add_plugin_option(p)
    p.add_argument("--k", nargs="+", type=fraction, default=list(PAPER_KS), help="reserve coefficients in [0, 1]")
    p.add_argument("--night-modes", nargs="+", default=list(NIGHT_MODES), choices=NIGHT_MODES)
    p.add_argument(
        "--night",
        default=DEFAULT_NIGHT,
        help="night hours: a clock window HH:MM-HH:MM (default the paper's 20:00-05:00) or 'sun'",
    )
    p.add_argument(
        "--forecast",
        nargs="+",
        default=["off", "oracle"],
        help="forecast sources: off, oracle (next step's actual) and/or a model name whose PV "
        "forecasts `opfbench forecast --dataset pv --out DIR` wrote (default: off oracle)",
    )
    p.add_argument(
        "--forecast-dir", type=path, default="reports/forecast", help="where model forecasts are (default reports/forecast)"
    )
    p.add_argument(
        "--acopf-solver",
        choices=ACOPF_SOLVERS,
        default="auto",
        help="auto (default): the SOCP certifies the AC optimum where it can, IPOPT solves the rest; "
        "ipopt: IPOPT on every step (its own convergence record)",
    )
    p.add_argument(
        "--fault-dir",
        type=path,
        default=None,
        help="a fault study's folder (`opfbench fault ... --out DIR`) for the report's fault section "
        "(default reports/fault, when it holds one)",
    )
    p.add_argument(
        "--year-dir",
        type=path,
        default=None,
        help="a year run's folder (`opfbench run --period year --out DIR`) for the report's year section "
        "(default reports/year when it holds one, else the committed docs/year summary)",
    )
    p.add_argument(
        "--period",
        default="paper-day",
        help="paper-day (default; 1 min, BSRN PV), year (2016 at 15 min, SimBench PV3) or START..END (local times, END excluded)",
    )
    p.add_argument("--step-minutes", type=_minutes, default=None, help="override the period's step (minutes)")
    p.add_argument(
        "--chunk",
        choices=CHUNKS,
        default="auto",
        help="steps per task: a local quarter day (6h), day, week or month; auto (default): 6h for "
        "periods of up to two days, else month (fixed by the config, independent of workers)",
    )
    p.add_argument(
        "--detail",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also write the long tables of per-DER Q and per-bus V (default: per-DER Q only, and only "
        "for periods of ≤ 2 days: the report plots it)",
    )
    p.add_argument(
        "--frontier",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="solve the optimum's frontier the rules are compared with at equal compliance (default); "
        "--no-frontier: the rules alone (loss-only figures), e.g. on a feeder too large for the three-phase OPF",
    )
    add_execution_options(p)
    p.add_argument(
        "--price",
        type=fraction,
        default=DEFAULT_PRICE_PER_KWH,
        help=f"price of lost energy per kWh for the report (default {DEFAULT_PRICE_PER_KWH} {DEFAULT_CURRENCY}, Eurostat 2023-H2 non-household)",
    )
    p.add_argument("--currency", default=DEFAULT_CURRENCY)
    p.add_argument("--out", type=path, default=Path("reports/run"), help="run folder (default reports/run)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _forecast_strategies(args: argparse.Namespace) -> list[str] | None:
    """--forecast-strategies as labels (None: every strategy that reads a forecast)."""
    chosen = args.forecast_strategies
    if chosen is None:
        return None if args.strategies else list(DEFAULT_FORECAST)
    return None if chosen == ["all"] else strategy_labels(chosen, args)


def run(args: argparse.Namespace) -> int:
    source = DEFAULT_PRICE_SOURCE if args.price == DEFAULT_PRICE_PER_KWH else "--price"
    from opfbench.commands.progress import console
    from opfbench.report.inputs import checked_sources
    from opfbench.report.sources import holds_forecasts
    from opfbench.study.run_family import run_study

    forecast_dir = Path(args.forecast_dir)  # the report's forecast section only when it holds a forecast run
    checked_sources(forecast_dir if holds_forecasts(forecast_dir) else None, args.fault_dir, args.year_dir)  # before any work
    config = StudyConfig.build(
        cases=[case_spec(c, args) for c in suite_cases(args.suite) or args.case or ["paper33"]],
        strategies=strategy_labels(args.strategies or list(DEFAULT_RUN), args),
        forecast_strategies=_forecast_strategies(args),
        ks=args.k,
        night_modes=args.night_modes,
        night=args.night,
        forecast=args.forecast,
        period=args.period,
        step_minutes=args.step_minutes,
        chunk=args.chunk,
        detail=args.detail,
        acopf_solver=args.acopf_solver,
        frontier=args.frontier,
        forecast_dir=str(args.forecast_dir),
        price_per_kwh=args.price,
        currency=args.currency,
        price_source=source,
    )
    result = run_study(
        config,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        fresh=args.fresh,
        command=["opfbench", *sys.argv[1:]],
        reporter=console(args.quiet),
    )
    return finish_run(result, args)


def finish_run(result: StudyRun, args: argparse.Namespace) -> int:
    """The end of a run: steps.parquet and summary.csv are assembled; report and print."""
    from opfbench.report import write_report
    from opfbench.report.sources import holds_forecasts, report_sources

    forecast_dir = Path(args.forecast_dir)
    forecast, fault, year = report_sources(forecast_dir if holds_forecasts(forecast_dir) else None, args.fault_dir, args.year_dir)
    report = write_report(result.out, forecast, fault, year_dir=year)
    summary = result.summary
    assert summary is not None, "run_study returns the summary of a finished run"
    if args.json:
        print_json(summary.to_dict(orient="records"))
        return 0
    cols = [
        "case",
        "strategy",
        "k",
        "night_mode",
        "forecast",
        "avg_loss_kw",
        "energy_kwh",
        "savings_pct",
        "curtailed_kwh",
        "not_ok_steps",
        "voltage_violation_steps",
        "gap_pct",
        "gap_eq_pct",
        "share_eq_pct",
    ]
    print(summary[cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(
        f"\n{len(result.tasks)} tasks ({result.ran} run now, {len(result.tasks) - result.ran} kept), "
        f"{result.wall_s:.1f} s; per-step table: {result.out / 'steps.parquet'}   summary: {result.out / 'summary.csv'}"
    )
    print(f"report: {report}")
    return 0
