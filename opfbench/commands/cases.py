"""`opfbench cases`: the shipped cases with bus/branch/DER counts."""

from __future__ import annotations

import argparse

from opfbench.commands.common import print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cases", help="list the shipped cases")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.cases import CASE_NAMES, load_case

    rows = [load_case(name).summary() for name in CASE_NAMES]
    if args.json:
        print_json(rows)
        return 0
    print(f"{'case':<16}{'buses':>6}{'branches':>9}{'open':>6}{'DER':>5}  meshed  load MW / MVAr")
    for r in rows:
        print(
            f"{r['case']:<16}{r['buses']:>6}{r['branches']:>9}{r['branches_open']:>6}{r['ders']:>5}  "
            f"{'yes' if r['meshed'] else 'no':<6}  {r['load_mw']:.3f} / {r['load_mvar']:.3f}"
        )
    return 0
