"""The paper day's headline loss energies, pinned: every registered strategy at k = 0, PV
connected at night, no forecast, on paper33 over the 1440 one-minute steps of
`opfbench.data.paper_day()`, pinned from a run of 2026-11-23 (the grid codes' rules of
issue 19 from a run of their own: Volt-VAR and Q(U) settled closed loop); the tolerance
(0.5 %) lets solver round-off through and fails a 1 % regression. `acopf-paper` (the same AC OPF with
the paper's slack rule and fallback) gives the same energy on this day; it runs with the
slow studies. What the day costs is the benchmarks' business (`python -m opfbench.bench
opf`, README).
"""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.data import paper_day
from opfbench.io import load_network
from opfbench.registry import DEFAULT_RUN, run_strategy
from opfbench.result import OK
from opfbench.scenario import Scenario

HEADLINE_KWH = {
    "no-action": 804.50,
    "llma": 750.97,
    "lfma": 482.34,
    "volt-var": 764.29,
    "watt-var": 926.28,
    "const-pf": 1043.96,
    "cosphi-p": 949.98,
    "q-u": 647.89,
    "acopf": 457.95,
    "acopf-paper": 457.95,
    "socp": 457.95,
}
TOLERANCE = 0.005  # relative
SLOW = {"acopf-paper"}


@pytest.fixture(scope="module")
def day_scenario() -> Scenario:
    day = paper_day()
    return Scenario.from_profiles(load_network("paper33"), day["load"].to_numpy(), day["pv"].to_numpy(), day["wind"].to_numpy())


def test_every_registered_strategy_has_a_pinned_energy():
    assert set(HEADLINE_KWH) == set(DEFAULT_RUN)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in DEFAULT_RUN])
def test_paper_day_energy_at_k0(day_scenario, name):
    result = run_strategy(name, day_scenario, 0.0)
    assert np.all(result.status == OK)
    energy_kwh = float(result.losses_kw.sum()) / 60  # 1-min steps: kW·min → kWh
    assert energy_kwh == pytest.approx(HEADLINE_KWH[name], rel=TOLERANCE)
