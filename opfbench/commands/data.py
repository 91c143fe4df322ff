"""`opfbench data`: list the embedded derived time series."""

from __future__ import annotations

import argparse

from opfbench.jsonio import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("data", help="list the embedded time series (rows, span, step, units, gaps filled)")
    parser.add_argument(
        "--json", action="store_true", help="print a JSON list of {name, rows, start, end, step, columns, gaps_filled}"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.data.loaders import describe_datasets

    summaries = describe_datasets()
    if args.json:
        print_json(summaries)
        return 0
    for s in summaries:
        print(f"{s['name']}: {s['rows']} rows, {s['start']} .. {s['end']}, step {s['step']}")
        for col, unit in s["columns"].items():
            print(f"  {col:<24} {unit:<6} gaps filled {s['gaps_filled'][col]}")
    return 0
