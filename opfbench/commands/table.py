"""`opfbench table [CASE]`: the local rules' loss table on one operating point — every local
rule the registry lists (no action, LLMA, LFMA, the grid codes' rules) at its defaults, for
the paper's reserve coefficients k, without and with a forecast (Algorithm 3).

Forecast rule: P^F = min(factor · P^C, P̄) per DER (factor 1.2 = a +20 % forecast), with
P^C = der_scale · P̄. The rules and their options come from the registry.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Sequence

from opfbench.capability import PAPER_KS
from opfbench.commands.arguments import fraction, print_json, share
from opfbench.io.sources import formats

if TYPE_CHECKING:
    import pandas as pd

FORECAST_FACTOR = 1.2


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


def loss_table(
    case: str = "paper33",
    ks: Sequence[float] = PAPER_KS,
    load_scale: float = 1.0,
    der_scale: float = 0.8,
    forecast_factor: float = FORECAST_FACTOR,
    safe: bool = False,
) -> "pd.DataFrame":
    """One row per (forecast, k, strategy): losses_kw, excursion_mvar, status, vmin.
    `forecast` is False (plain rules) or True (Algorithm 3 with the forecast rule above)."""
    import pandas as pd

    from opfbench.io import load_network
    from opfbench.registry.catalog import run_strategy
    from opfbench.scenario import Scenario

    net = load_network(case)
    scenarios = {  # every DER at the same share of its rating, so the rule is a share too
        False: Scenario.snapshot(net, load_scale, der_scale),
        True: Scenario.snapshot(net, load_scale, der_scale, min(forecast_factor * der_scale, 1.0)),
    }
    rows = []
    for forecast, scenario in scenarios.items():
        for k in ks:
            for spec in local_rules():
                name = spec.name
                options = {"safe": safe} if "safe" in spec.option else {}
                res = run_strategy(name, scenario, k, None, **options)
                rows.append(
                    {
                        "forecast": forecast,
                        "k": float(k),
                        "strategy": name,
                        "losses_kw": float(res.losses_kw[0]),
                        "excursion_mvar": float(res.excursion_mvar[0]),
                        "status": str(res.status[0]),
                        "vmin": float(res.vmin[0]),
                    }
                )
    return pd.DataFrame(rows)


def local_rules() -> list:
    """Every registered local rule that runs at its default options (not the learned ones), in registry order."""
    from opfbench.registry.catalog import specs

    return [s for s in specs() if s.kind == "local" and not s.learned]


def format_table(table: "pd.DataFrame") -> str:
    """Losses (kW) as k × strategy, one block per forecast setting, plus the largest
    excursion over the physical capability (MVAr) and any status other than ok."""
    blocks = []
    for forecast, part in table.groupby("forecast", sort=True):
        wide = part.pivot(index="k", columns="strategy", values="losses_kw")[[s.name for s in local_rules()]]
        wide["max excursion MVAr"] = part.groupby("k")["excursion_mvar"].max()
        title = "with forecast (Algorithm 3)" if forecast else "without forecast"
        blocks.append(f"{title} — losses kW\n{wide.to_string(float_format=lambda v: f'{v:.3f}')}")
    bad = table[table["status"] != "ok"]
    if not bad.empty:
        blocks.append("not ok:\n" + bad.to_string(index=False))
    return "\n\n".join(blocks)
