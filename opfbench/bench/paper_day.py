"""The operating points the benchmarks use: the paper day (1440 × 1 min, real data:
BSRN Payerne PV, SimBench wind and load; see `opfbench.data.paper_day`)."""

from __future__ import annotations

from opfbench.data import paper_day
from opfbench.io import load_network
from opfbench.scenario import Scenario


def paper_day_scenario(case: str = "paper33") -> Scenario:
    """1440 one-minute snapshots of the paper day on `case`."""
    day = paper_day()
    return Scenario.from_profiles(load_network(case), day["load"].to_numpy(), day["pv"].to_numpy(), day["wind"].to_numpy())
