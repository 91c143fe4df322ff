"""Loss table of the local rules on one operating point: no action, LLMA and LFMA for a
sweep of reserve coefficients k, without and with a forecast (Algorithm 3).

Forecast rule: P^F = min(factor · P^C, P̄) per DER (factor 1.2 = a +20 % forecast),
with P^C = der_scale · P̄. The rules and their options come from the registry.

    python -m opfbench.strategies.table [--case paper33] [--der-scale 0.8] [--safe]
"""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

import numpy as np
import pandas as pd

from opfbench.commands.common import fraction
from opfbench.errors import OpfbenchError
from opfbench.io import load_network
from opfbench.registry import LOCAL_RULES, STRATEGIES, run_strategy
from opfbench.scenario import Scenario

PAPER_KS = (0.0, 0.2, 0.4, 0.6, 0.8)
FORECAST_FACTOR = 1.2


def forecast_p_mw(p_mw: np.ndarray, rating_mw: np.ndarray, factor: float = FORECAST_FACTOR) -> np.ndarray:
    """The table's forecast rule P^F = min(factor · P^C, P̄), in MW."""
    return np.minimum(factor * np.asarray(p_mw, float), rating_mw)


def loss_table(
    case: str = "paper33",
    ks: Sequence[float] = PAPER_KS,
    load_scale: float = 1.0,
    der_scale: float = 0.8,
    forecast_factor: float = FORECAST_FACTOR,
    safe: bool = False,
) -> pd.DataFrame:
    """One row per (forecast, k, strategy): losses_kw, excursion_mvar, status, vmin.
    `forecast` is False (plain rules) or True (Algorithm 3 with the forecast rule above)."""
    net = load_network(case)
    scenarios = {  # every DER at the same share of its rating, so the rule is a share too
        False: Scenario.snapshot(net, load_scale, der_scale),
        True: Scenario.snapshot(net, load_scale, der_scale, min(forecast_factor * der_scale, 1.0)),
    }
    rows = []
    for forecast, scenario in scenarios.items():
        for k in ks:
            for name in LOCAL_RULES:
                options = {"safe": safe} if "safe" in STRATEGIES[name].options else {}
                res = run_strategy(name, scenario, k, **options)
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


def format_table(table: pd.DataFrame) -> str:
    """Losses (kW) as k × strategy, one block per forecast setting, plus the largest
    excursion over the physical capability (MVAr) and any status other than ok."""
    blocks = []
    for forecast, part in table.groupby("forecast", sort=True):
        wide = part.pivot(index="k", columns="strategy", values="losses_kw")[list(LOCAL_RULES)]
        wide["max excursion MVAr"] = part.groupby("k")["excursion_mvar"].max()
        title = "with forecast (Algorithm 3)" if forecast else "without forecast"
        blocks.append(f"{title} — losses kW\n{wide.to_string(float_format=lambda v: f'{v:.3f}')}")
    bad = table[table["status"] != "ok"]
    if not bad.empty:
        blocks.append("not ok:\n" + bad.to_string(index=False))
    return "\n\n".join(blocks)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.strategies.table", description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="paper33", help="shipped case name or MATPOWER .m path")
    parser.add_argument("--load-scale", type=fraction, default=1.0)
    parser.add_argument("--der-scale", type=fraction, default=0.8, help="P^C as a fraction of rating, 0..1")
    parser.add_argument(
        "--forecast-factor", type=fraction, default=FORECAST_FACTOR, help="P^F = min(factor · P^C, rating) (default 1.2)"
    )
    parser.add_argument("--safe", action="store_true", help="clip to the physical capability at P^C")
    args = parser.parse_args(argv)
    try:
        table = loss_table(args.case, PAPER_KS, args.load_scale, args.der_scale, args.forecast_factor, args.safe)
    except OpfbenchError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(
        f"{args.case}: load ×{args.load_scale:g}, P^C = {args.der_scale:g}·P̄, "
        f"P^F = min({args.forecast_factor:g}·P^C, P̄){', safe' if args.safe else ''}\n"
    )
    print(format_table(table))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
