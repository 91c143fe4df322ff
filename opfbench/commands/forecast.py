"""`opfbench forecast`: compare one-step-ahead PV / wind forecasters (paper §II, Table I).

Full run (tens of minutes per dataset; the README gives today's figures):
    opfbench forecast --dataset pv --out reports/forecast
    opfbench forecast --dataset wind --out reports/forecast
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from typing import TYPE_CHECKING

from opfbench.commands.arguments import path
from opfbench.errors import InputError
from opfbench.forecasting.names import FORECAST_DATASETS, MODEL_NAMES
from opfbench.jsonio import print_json

if TYPE_CHECKING:
    from opfbench.forecasting.experiment import ComparisonResult

SEED_MAX = 2**32 - 1  # numpy's seed range; torch accepts it too

METRIC_COLUMNS = (("mse_scaled", ".5f"), ("mape_pct", ".2f"), ("mae_kw", ".4f"), ("rmse_kw", ".4f"), ("skill", ".3f"))


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "forecast",
        help="compare persistence, ARIMA, LSTM, CNN-LSTM and Wavelet-CNN-LSTM one-step forecasts",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--dataset", required=True, choices=FORECAST_DATASETS)
    parser.add_argument(
        "--models",
        default=",".join(MODEL_NAMES),
        help=f"comma-separated subset of {','.join(MODEL_NAMES)} (persistence always runs: it is the skill reference)",
    )
    parser.add_argument("--quick", action="store_true", help="smoke run: a few days of data, 2 short epochs")
    parser.add_argument("--out", metavar="DIR", type=path, help="write forecast_<dataset>.csv/.json/.html into DIR")
    parser.add_argument("--seed", type=int, default=0, help=f"random seed in [0, {SEED_MAX}] (default 0)")
    parser.add_argument(
        "--weather",
        choices=("target", "previous"),
        default="target",
        help="weather input at the target time (paper: a perfect weather forecast) or one step earlier",
    )
    parser.add_argument("--threads", type=int, help="torch CPU threads (default 1: robust on a shared machine)")
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.folders import check_out_dir
    from opfbench.forecasting.datasets import forecast_dataset
    from opfbench.forecasting.experiment import run_comparison
    from opfbench.forecasting.models import settings_for
    from opfbench.forecasting.outputs import write_outputs

    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    if not models:
        raise InputError("--models is empty")
    unknown = [m for m in models if m not in MODEL_NAMES]
    if unknown:
        raise InputError(f"--models: unknown model(s) {', '.join(unknown)}; choose from {', '.join(MODEL_NAMES)}")
    if not 0 <= args.seed <= SEED_MAX:
        raise InputError(f"--seed must lie in [0, {SEED_MAX}], got {args.seed}")
    settings = settings_for(args.dataset, args.quick)
    if args.threads is not None:
        cores = os.cpu_count() or 1
        if not 1 <= args.threads <= cores:  # more threads than cores only contend (and thousands exhaust memory)
            raise InputError(f"--threads lies in 1..{cores} (this machine's CPU cores), got {args.threads}")
        settings = replace(settings, threads=args.threads)
    if args.out is not None:  # before the computation, not after it
        check_out_dir(args.out)
    dataset = forecast_dataset(args.dataset).lag_weather(1 if args.weather == "previous" else 0)
    result = run_comparison(dataset, models, settings, args.seed, progress=lambda msg: print(msg, file=sys.stderr))
    if args.out is not None:
        from opfbench.forecasting.outputs import forecast_path
        from opfbench.jsonio import write_atomic
        from opfbench.report.forecast_page import forecast_page  # matplotlib only when a page is drawn

        written = write_outputs(result, args.out)
        written.append(write_atomic(forecast_path(args.out, result.dataset, "html"), forecast_page(result)))
        for one in written:
            print(f"wrote {one}", file=sys.stderr)
    if args.json:
        print_json(result.metrics_table())
    else:
        print(format_table(result))
    return 0


def format_table(result: "ComparisonResult") -> str:
    """Plain-text metrics table with the paper's Table I values."""
    from opfbench.report.paper_figures import FORECAST_TABLE as PAPER_TABLE

    header = (
        f"{'model':<18}"
        + "".join(f"{name:>12}" for name, _ in METRIC_COLUMNS)
        + f"{'fit_s':>9}{'paper_mse':>11}{'paper_mape':>11}"
    )
    lines = [
        f"{result.dataset}: {len(result.forecasts)} test steps from {result.forecasts.index[0]}, "
        f"MAPE on actual > {result.settings.mape_threshold:.0%} of {result.rating_kw:g} kW, "
        f"weather lag {result.weather_lag} step(s), seed {result.seed}",
        header,
    ]
    for name, run in result.runs.items():
        values = run.as_dict()
        paper = PAPER_TABLE.get(result.dataset, {}).get(name)
        cells = "".join(f"{format(values[key], spec):>12}" for key, spec in METRIC_COLUMNS)
        reference = f"{paper[0]:>11.4f}{paper[1]:>11.2f}" if paper else f"{'-':>11}{'-':>11}"
        lines.append(f"{name:<18}{cells}{values['fit_s']:>9.1f}{reference}")
    return "\n".join(lines)
