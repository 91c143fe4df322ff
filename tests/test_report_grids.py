"""The report's per-grid leaderboard and the ranking claim checked per grid, on a summary
whose energies are set by hand (each table's rule is checked, not a run)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.report.claims import FAILS, HOLDS, ranking_per_case
from opfbench.report.tables import Kinds, how_close, leaderboard


def _summary() -> pd.DataFrame:
    energy = {  # case → strategy → kWh, at k = 0, night connected, forecast off
        "grid-a": {"no-action": 100.0, "llma": 96.0, "lfma": 90.0, "acopf": 80.0, "socp": 80.0},
        "grid-b": {"no-action": 50.0, "llma": 51.0, "lfma": 49.0, "acopf": 48.0, "socp": 48.0},
    }
    rows = [
        {
            "case": case,
            "strategy": s,
            "k": 0.0,
            "night_mode": "connected",
            "forecast": "off",
            "energy_kwh": e,
            "no_action_kwh": by["no-action"],
            "savings_pct": 100 * (1 - e / by["no-action"]),
            "voltage_violation_steps": 3 if s == "llma" else 0,
            "not_ok_steps": 0,
        }
        for case, by in energy.items()
        for s, e in by.items()
    ]
    return pd.DataFrame(rows)


def test_leaderboard_shares_of_the_opf_reduction():
    board = leaderboard(_summary()).set_index(["case", "strategy"])
    assert board.loc[("grid-a", "lfma"), "loss_only_share_pct"] == pytest.approx(50.0)
    assert board.loc[("grid-a", "llma"), "loss_only_share_pct"] == pytest.approx(20.0)
    assert board.loc[("grid-b", "llma"), "loss_only_share_pct"] == pytest.approx(-50.0)  # worse than no action
    assert board.loc[("grid-a", "acopf"), "rank"] == 1 and board.loc[("grid-a", "llma"), "rank"] == 4
    assert board.loc[("grid-a", "llma"), "voltage_violation_steps"] == 3 and "no-action" not in board.index.get_level_values(1)


def test_leaderboard_without_an_opf_reduction_gives_no_share():
    s = _summary()
    s.loc[s.strategy == "acopf", "energy_kwh"] = s.loc[s.strategy == "acopf", "no_action_kwh"]
    assert np.isnan(leaderboard(s).loss_only_share_pct).all()


def test_ranking_claim_per_grid():
    table = ranking_per_case(_summary()).set_index("case")
    assert table.loc["grid-a", "verdict"] == HOLDS and table.loc["grid-a", "ordered"] == 1
    assert table.loc["grid-b", "verdict"] == FAILS and "grid-b, night connected, k=0" in table.loc["grid-b", "first exception"]


def test_leaderboard_columns_and_the_recovery_added_from_a_fault_study():
    s = _summary().assign(avg_loss_kw=4.0, voltage_violation_min=0.0, max_violation_pu=0.0, not_settled_steps=0)
    s.loc[s.strategy == "llma", ["voltage_violation_min", "max_violation_pu"]] = (3.0, 0.012)
    recovery = pd.DataFrame(
        {
            "case": "grid-a",
            "fault_bus": [18, 18, 18, 33, 33, 33],
            "strategy": ["no-action", "llma", "lfma"] * 2,
            "k": 0.0,
            "forecast": "off",
            "variant": "reference",
            "added_ms": [0.0, 4.0, 10.0, 0.0, 6.0, 30.0],
        }
    )
    board = leaderboard(s, recovery=recovery).set_index(["case", "strategy"])
    assert board.loc[("grid-a", "lfma"), "recovery_added_ms"] == pytest.approx(20.0)  # mean over the fault buses
    assert board.loc[("grid-a", "llma"), "recovery_added_ms"] == pytest.approx(5.0)
    assert np.isnan(board.loc[("grid-b", "lfma"), "recovery_added_ms"])  # no fault study of grid-b
    assert board.loc[("grid-a", "llma"), "max_violation_pu"] == 0.012 and board.loc[("grid-a", "llma"), "avg_loss_kw"] == 4.0
    assert "recovery_added_ms" not in leaderboard(s).columns  # without a fault study


def test_how_close_sets_train_beside_test_and_maps_a_perturbed_case_to_its_model():
    test = _summary().assign(voltage_violation_min=0.0, max_violation_pu=0.0, not_settled_steps=0)
    perturbed = test[test["case"] == "grid-a"].assign(case="grid-a?line-z=1.2")
    train = test[test["case"] == "grid-a"].copy()
    train.loc[train["strategy"] == "lfma", "energy_kwh"] = 85.0  # train: 75 % of the OPF's reduction
    both = pd.concat([test, perturbed])
    table = how_close(both, Kinds.of(both["strategy"]), train, {"grid-a?line-z=1.2": "grid-a"}).set_index(["case", "strategy"])
    assert "acopf" not in table.index.get_level_values(1) and "socp" not in table.index.get_level_values(1)
    assert table.loc[("grid-a", "no-action"), "test_loss_only_share_pct"] == 0.0
    assert table.loc[("grid-a", "lfma"), "test_loss_only_share_pct"] == pytest.approx(50.0)
    assert table.loc[("grid-a", "lfma"), "train_loss_only_share_pct"] == pytest.approx(75.0)
    assert table.loc[("grid-a?line-z=1.2", "lfma"), "train_loss_only_share_pct"] == pytest.approx(75.0)  # the model's training
    assert np.isnan(table.loc[("grid-b", "lfma"), "train_loss_only_share_pct"])  # no training on grid-b
    alone = how_close(test, Kinds.of(test["strategy"]))
    assert alone["train_loss_only_share_pct"].isna().all() and len(alone) == 6


def test_at_equal_compliance_the_leaderboard_and_how_close_rank_by_the_gap():
    """With the frontier's columns (a run since the frontier): ranked by the gap at equal
    compliance, fewer minutes outside first on a tie, the share there beside the loss-only
    one; a rule that leaves the band and loses least ranks below one that holds it."""
    s = _summary().assign(voltage_violation_min=0.0, max_violation_pu=0.0, not_settled_steps=0, curtailed_kwh=0.0)
    gaps = {"no-action": 5.0, "llma": 4.0, "lfma": 6.0, "acopf": 0.0, "socp": 0.0}
    s["gap_eq_kwh"] = s["strategy"].map(gaps)
    s["share_eq_pct"] = 100.0 - 10 * s["gap_eq_kwh"]
    s.loc[s.strategy == "socp", "voltage_violation_min"] = 15.0  # ties acopf's gap, less compliant
    board = leaderboard(s).set_index(["case", "strategy"])
    assert [board.loc[("grid-a", n), "rank"] for n in ("acopf", "socp", "llma", "lfma")] == [1, 2, 3, 4]
    assert board.loc[("grid-a", "lfma"), "energy_kwh"] < board.loc[("grid-a", "llma"), "energy_kwh"]  # lower losses, ranked below
    assert board.loc[("grid-a", "lfma"), "loss_only_share_pct"] == pytest.approx(50.0)
    table = how_close(s, Kinds.of(s["strategy"])).set_index(["case", "strategy"])
    ranks = [table.loc[("grid-a", n), "rank"] for n in ("llma", "no-action", "lfma")]  # the local rules alone
    assert ranks == [1, 2, 3]
    assert table.loc[("grid-a", "lfma"), "test_share_eq_pct"] == pytest.approx(40.0)
