"""The study grid: faults at buses 17 and 27 × {no action, LLMA, LFMA, AC OPF} × five k ×
forecast off/oracle on the paper feeder (slow), and the recovery table's bookkeeping
against no action (fast)."""

import numpy as np
import pandas as pd
import pytest

from opfbench.dynamics.params import FaultParams
from opfbench.dynamics.recovery import recovery_table
from opfbench.dynamics.study import FaultConfig, run_fault_study
from opfbench.io import load_case

CASE = load_case("paper33")
NET = CASE.network


def _table(config: FaultConfig, **kw) -> pd.DataFrame:
    study = run_fault_study(config, CASE, **kw)
    assert study.timings["simulations"] == study.timings["models"] * len(config.fault_buses)
    return study.table


def test_recovery_against_no_action():
    config = FaultConfig("paper33", (27,), ("no-action", "lfma"), (0.0, 0.8), fault=FaultParams(bus=0, t_end_s=1.0))
    table = _table(config)
    s = recovery_table(table)
    assert len(s) == 4 and set(s["slowest_bus"]) <= set(NET.bus_ids) and (s["feeder_status"] == "recovered").all()
    na = s[s["strategy"] == "no-action"]
    assert (na["added_feeder_ms"] == 0).all() and na["feeder_recovery_ms"].nunique() == 1  # k does not act on Q = 0
    lf = s[s["strategy"] == "lfma"].set_index("k")
    rows = table[(table["strategy"] == "lfma") & (table["k"] == 0.0)]
    worst = rows["recovery_ms"].max()
    assert lf.loc[0.0, "feeder_recovery_ms"] == pytest.approx(worst)
    assert lf.loc[0.0, "slowest_bus"] == rows.loc[rows["recovery_ms"].idxmax(), "bus"]
    assert lf.loc[0.0, "added_feeder_ms"] == pytest.approx(worst - na["feeder_recovery_ms"].iloc[0])
    at_27 = rows.loc[rows["bus"] == 27, "recovery_ms"].iloc[0] - na["recovery_ms"].iloc[0]
    assert lf.loc[0.0, "added_ms"] == pytest.approx(at_27)


def test_the_oracle_is_compared_with_no_action_too():
    """No action reads no forecast: it runs once, under "off", and every forecast's rows are
    measured against it (a join on the forecast would leave the oracle's without)."""
    table = pd.DataFrame(
        {
            "case": "c",
            "fault_bus": 5,
            "strategy": ["no-action", "llma", "llma"],
            "k": 0.0,
            "forecast": ["off", "off", "oracle"],
            "variant": "reference",
            "bus": 5,
            "recovery_ms": [150.0, 160.0, np.nan],
            "status": ["recovered", "recovered", "not-recovered"],
            "vmin_pu": 0.1,
            "margin_pu": [0.05, 0.04, -0.1],
            "faulted": True,
        }
    )
    s = recovery_table(table)
    assert s["added_ms"].tolist()[:2] == [0.0, 10.0] and np.isnan(s["added_ms"].iloc[2])
    assert s["feeder_status"].tolist() == ["recovered", "recovered", "not-recovered"]
    assert np.isnan(s["feeder_recovery_ms"].iloc[2])  # not recovered: no time, not infinity


@pytest.mark.slow
def test_reference_study_buses_17_and_27():
    config = FaultConfig("paper33", (17, 27), ("no-action", "llma", "lfma", "acopf"), forecasts=("off", "oracle"), time="09:00")
    table = _table(config, workers=2)
    n_cfg = 5 + 2 * 2 * 5 + 5  # no action at each k, LLMA/LFMA × forecast × k, AC OPF × k
    assert len(table) == 2 * n_cfg * NET.n_bus
    assert (table["status"] == "recovered").all() and (table["motors_stalled"] == 0).all()
    s = recovery_table(table)
    # at the fault bus the voltage is far below 0.9 during the fault: recovery ≥ the fault
    assert (s["recovery_ms"] >= 149.0).all() and (s["vmin_pu"] < 0.1).all()
    # the margin beside each time: recovered buses sit above 0.9 p.u. at the end
    assert (table["margin_pu"] > 0).all()
    lf = s[(s["strategy"] == "lfma") & (s["forecast"] == "off") & (s["fault_bus"] == 27)].sort_values("k")
    assert np.all(np.isfinite(lf["added_feeder_ms"]))
    assert s["added_ms"].notna().all()  # the oracle's rows too
