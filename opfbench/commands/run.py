"""`opfbench run`: the benchmark on the paper day — every strategy × k × night mode ×
forecast — writing the per-step table and the summary."""

from __future__ import annotations

import argparse
from pathlib import Path

from opfbench.study import NIGHT_MODES, BenchmarkConfig, run_benchmark, summarize
from opfbench.commands.common import fraction, print_json
from opfbench.registry import STRATEGY_NAMES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the benchmark on the paper day (the main job)")
    p.add_argument("--case", default="paper33", help="shipped case name or MATPOWER .m path (default paper33)")
    p.add_argument("--strategies", nargs="+", default=list(STRATEGY_NAMES), choices=STRATEGY_NAMES)
    p.add_argument("--k", nargs="+", type=fraction, default=[0.0, 0.2, 0.4, 0.6, 0.8], help="reserve coefficients")
    p.add_argument("--night-modes", nargs="+", default=list(NIGHT_MODES), choices=NIGHT_MODES)
    p.add_argument("--night", default="20:00-05:00",
                   help="night hours: a clock window (default the paper's 20:00-05:00) or 'sun' (sunset→sunrise)")
    p.add_argument("--forecast", nargs="+", default=["off", "oracle"],
                   help="forecast sources: off, oracle (next step's actual) and/or a model name whose PV "
                        "forecasts `opfbench forecast --dataset pv --out DIR` wrote (default: off oracle)")
    p.add_argument("--forecast-dir", default="reports/forecast", help="where model forecasts are (default reports/forecast)")
    p.add_argument("--out", type=Path, default=Path("reports/run"), help="output folder (default reports/run)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    config = BenchmarkConfig(args.case, tuple(args.strategies), tuple(args.k), tuple(args.night_modes),
                             args.night, tuple(args.forecast), args.forecast_dir)
    table = run_benchmark(config)
    summary = summarize(table)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_parquet(args.out / "steps.parquet", index=False)
    summary.to_csv(args.out / "summary.csv", index=False, float_format="%.6g")
    if args.json:
        print_json(summary.to_dict(orient="records"))
        return 0
    cols = ["strategy", "k", "night_mode", "forecast", "avg_loss_kw", "energy_kwh", "savings_pct",
            "not_ok_steps", "voltage_violation_steps", "max_excursion_mvar"]
    print(summary[cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(f"\nper-step table: {args.out / 'steps.parquet'}   summary: {args.out / 'summary.csv'}")
    return 0
