"""The local rules' loss table on one operating point (the paper's Table II done for every
local rule): every registered local rule at its defaults (no action, LLMA, LFMA, the grid
codes' rules; not the learned ones, which need parameters), for the given reserve
coefficients k, without and with a forecast (Algorithm 3) — `opfbench table` prints it.

Forecast rule: P^F = min(factor · P^C, P̄) per DER (factor 1.2 = a +20 % forecast), with
P^C = der_scale · P̄. Every DER at the same share of its rating, so a rule's target is a
share too.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from opfbench.capability import PAPER_KS
from opfbench.registry.catalog import run_strategy, specs
from opfbench.registry.specs import StrategySpec

if TYPE_CHECKING:
    import pandas as pd

FORECAST_FACTOR = 1.2  # P^F = min(factor · P^C, P̄): a +20 % forecast (light to import: the CLI's default)


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
    import pandas as pd

    from opfbench.io import load_network
    from opfbench.scenario import Scenario

    net = load_network(case)
    scenarios = {
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


def local_rules() -> list[StrategySpec]:
    """Every registered local rule that runs at its default options (not the learned ones), in catalog order."""
    return [s for s in specs() if s.kind == "local" and not s.learned]
