"""`opfbench table [CASE]`: the local rules' loss table on one operating point
(`study.loss_table`), printed as k × rule blocks without and with a forecast, or as JSON.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from opfbench.capability import PAPER_KS
from opfbench.commands.arguments import fraction, print_json, share
from opfbench.io.sources import formats
from opfbench.study.loss_table import FORECAST_FACTOR

if TYPE_CHECKING:
    import pandas as pd


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("table", help="the local rules' loss table on one operating point, k × rule, ± forecast")
    p.add_argument("case", nargs="?", default="paper33", help=f"the case (default paper33): {formats()}")
    p.add_argument("--load-scale", type=fraction, default=1.0, help="multiplier on every nominal load (default 1.0)")
    p.add_argument("--der-scale", type=share, default=0.8, help="P^C as a fraction of rating, 0..1 (default 0.8)")
    p.add_argument(
        "--forecast-factor", type=fraction, default=FORECAST_FACTOR, help="P^F = min(factor · P^C, rating) (default 1.2)"
    )
    p.add_argument("--safe", action="store_true", help="Algorithm 3: clip to the physical capability at P^C")
    p.add_argument("--json", action="store_true", help="print the rows as one JSON list")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.study.loss_table import loss_table

    table = loss_table(args.case, PAPER_KS, args.load_scale, args.der_scale, args.forecast_factor, args.safe)
    if args.json:
        print_json(table.to_dict(orient="records"))
        return 0
    print(
        f"{args.case}: load ×{args.load_scale:g}, P^C = {args.der_scale:g}·P̄, "
        f"P^F = min({args.forecast_factor:g}·P^C, P̄){', safe' if args.safe else ''}\n"
    )
    print(format_table(table))
    return 0


def format_table(table: "pd.DataFrame") -> str:
    """Losses (kW) as k × strategy, one block per forecast setting, plus the largest
    excursion over the physical capability (MVAr) and any status other than ok."""
    blocks = []
    for forecast, part in table.groupby("forecast", sort=True):
        wide = part.pivot(index="k", columns="strategy", values="losses_kw")[list(dict.fromkeys(part["strategy"]))]
        wide["max excursion MVAr"] = part.groupby("k")["excursion_mvar"].max()
        title = "with forecast (Algorithm 3)" if forecast else "without forecast"
        blocks.append(f"{title} — losses kW\n{wide.to_string(float_format=lambda v: f'{v:.3f}')}")
    bad = table[table["status"] != "ok"]
    if not bad.empty:
        blocks.append("not ok:\n" + bad.to_string(index=False))
    return "\n\n".join(blocks)
