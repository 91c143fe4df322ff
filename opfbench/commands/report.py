"""`opfbench report`: rebuild the HTML report of a run folder from the files a run, a
forecast run and a fault study wrote, without recomputing anything."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from opfbench.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="write the HTML report of a run folder (report.html)", description=__doc__)
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="folder written by `opfbench run --out RUN_DIR`")
    p.add_argument(
        "--forecast-dir",
        type=Path,
        help="folder written by `opfbench forecast --out DIR` "
        "(default reports/forecast when it holds one, else the "
        "committed docs/forecast metrics)",
    )
    p.add_argument(
        "--fault-dir",
        type=Path,
        help="folder written by `opfbench fault ... --out DIR` (default reports/fault when it holds one)",
    )
    p.add_argument(
        "--year-dir",
        type=Path,
        help="folder written by `opfbench run --period year --out DIR` "
        "(default reports/year when it holds one, else the committed "
        "docs/year summary)",
    )
    p.add_argument("--out", type=Path, help="report file (default RUN_DIR/report.html)")
    p.add_argument(
        "--price",
        type=float,
        help="energy price per kWh for the money rows (default: the run's manifest, else 0.20 EUR/kWh, Eurostat 2023-H2)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.report import write_report
    from opfbench.report.sources import check_year_dir, report_sources

    if not args.run_dir.is_dir():
        raise InputError(f"run folder {args.run_dir} does not exist; write it with `opfbench run --out {args.run_dir}`")
    for name in ("forecast_dir", "fault_dir", "year_dir"):
        folder = getattr(args, name)
        if folder is not None and not folder.is_dir():
            raise InputError(f"--{name.replace('_', '-')} {folder} does not exist")
    if args.price is not None and not (math.isfinite(args.price) and args.price >= 0):
        raise InputError(f"--price must be a finite number ≥ 0, got {args.price}")
    check_year_dir(args.year_dir)
    forecast_dir, fault_dir, year_dir = report_sources(args.forecast_dir, args.fault_dir, args.year_dir)
    path = write_report(args.run_dir, forecast_dir, fault_dir, args.out, args.price, year_dir)
    print(f"wrote {path}", file=sys.stderr)
    return 0
