"""Recovery per simulation and against no action: the one comparison of a fault study's
strategies with the baseline (`registry.BASELINE`), read by `opfbench fault` and the
report (light: no simulation code, no numba)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.dynamics.params import DIVERGED, NOT_RECOVERED, RECOVERED
from opfbench.registry.catalog import get_strategy
from opfbench.registry.references import BASELINE

WORST_FIRST = (DIVERGED, NOT_RECOVERED, RECOVERED)
"""A simulation's status is its worst bus's, in this order."""
KEYS = ["case", "fault_bus", "strategy", "k", "forecast", "variant"]
"""A simulation's keys in a `fault.parquet` table."""


def recovery_table(fault: pd.DataFrame) -> pd.DataFrame:
    """One row per simulation of a `fault.parquet` table (its KEYS, in the table's order):
    at the faulted bus its recovery_ms, status, vmin_pu and margin_pu (and motors_stalled
    where the table has it); the feeder's recovery — its slowest bus (a bus that did not
    recover is the slowest): slowest_bus, feeder_recovery_ms, slowest_margin_pu, and the
    simulation's status, its worst bus's (`WORST_FIRST`): feeder_status; and both
    recoveries minus the baseline's (no action) in the same case, variant, fault bus and
    k — under the same forecast if the registry says the baseline reads one, else its
    forecast-off simulation: added_ms, added_feeder_ms (ms; positive = slower than no
    action; NaN where either did not recover or the study has no baseline)."""
    at_fault = ["recovery_ms", "status", "vmin_pu", "margin_pu"] + (["motors_stalled"] if "motors_stalled" in fault else [])
    out = fault.loc[fault["faulted"].astype(bool), KEYS + at_fault].reset_index(drop=True)
    slowest = fault.assign(_rec=fault["recovery_ms"].fillna(np.inf)).groupby(KEYS, sort=False)["_rec"].idxmax()
    feeder = fault.loc[slowest.to_numpy(), KEYS + ["bus", "recovery_ms", "margin_pu"]]
    feeder.columns = KEYS + ["slowest_bus", "feeder_recovery_ms", "slowest_margin_pu"]
    rank = fault["status"].map({status: i for i, status in enumerate(WORST_FIRST)})
    worst = rank.groupby([fault[k] for k in KEYS], sort=False).min().map(dict(enumerate(WORST_FIRST)))
    feeder = feeder.join(worst.rename("feeder_status"), on=KEYS)
    out = out.merge(feeder, on=KEYS, how="left", sort=False)
    same = ["case", "variant", "fault_bus", "k"] + (["forecast"] if get_strategy(BASELINE).uses_forecast else [])
    base = out[(out["strategy"] == BASELINE) & ((out["forecast"] == "off") | ("forecast" in same))]
    base = base.drop_duplicates(same).set_index(same)[["recovery_ms", "feeder_recovery_ms"]]
    out = out.join(base.rename(columns=lambda c: f"_base_{c}"), on=same)
    out["added_ms"] = out["recovery_ms"] - out.pop("_base_recovery_ms")
    out["added_feeder_ms"] = out["feeder_recovery_ms"] - out.pop("_base_feeder_recovery_ms")
    return out
