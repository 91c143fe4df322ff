"""A snapshot-wise strategy (`StrategySpec.snapshot_wise`) runs once on the distinct
snapshots of a chunk's night modes (`study.task_scenarios.SharedSnapshots`): every mode's rows
are what its own run gives, bit for bit."""

import numpy as np
import pytest

from opfbench.registry.catalog import run_strategy, specs
from opfbench.study.config import NIGHT_MODES
from opfbench.study.periods import resolve_period
from opfbench.study.task_scenarios import SharedSnapshots, chunk_scenario

EVENING = "2016-06-28T19:00..2016-06-28T21:30"  # day and night rows, PV still producing after 20:00
WALKED = ("q_mvar", "losses_kw", "vm", "status", "power_flows", "excursion_mvar", "lower_bound_kw", "curtailed_kw")


@pytest.fixture(scope="module")
def modes():
    p = resolve_period(EVENING, "20:00-05:00")
    step = p.index[1] - p.index[0]
    return [chunk_scenario("paper33", mode, "oracle", p.profiles, p.night, len(p.index), step, ".") for mode in NIGHT_MODES]


def test_the_union_holds_each_distinct_snapshot_once(modes):
    shared = SharedSnapshots.of(modes)
    n = modes[0].n_snapshots
    night = modes[2].pv_night_q
    on, off, night_q = (modes[0].same_rows(m) for m in modes)
    assert on.all() and not off.all() and (night_q == ~night).all()  # by day all three are one
    assert shared.owned[0] == n and shared.owned[2] == night.sum() and shared.union.n_snapshots == sum(shared.owned)
    for scenario, rows in zip(modes, shared.rows, strict=True):
        assert shared.union.take(rows).same_rows(scenario).all()
    assert sum(shared.share(j) for j in range(3)) == pytest.approx(1.0)


@pytest.mark.parametrize(
    "name", [s.name for s in specs() if s.snapshot_wise and s.source == "opfbench" and not s.learned and "radial" in s.supports]
)
def test_a_snapshot_wise_strategy_gives_each_mode_its_own_results_from_the_union(modes, name):
    shared = SharedSnapshots.of(modes)
    union = run_strategy(name, shared.union, 0.2)
    for scenario, rows in zip(modes, shared.rows, strict=True):
        own, taken = run_strategy(name, scenario, 0.2), union.take(rows, 0.0)
        for field in WALKED:
            np.testing.assert_array_equal(getattr(taken, field), getattr(own, field), err_msg=f"{name}: {field}")
        assert taken.extra.keys() == own.extra.keys()
        for key, value in own.extra.items():
            if key not in ("solves",):  # the screening guesses a solve took
                np.testing.assert_array_equal(taken.extra[key], value, err_msg=f"{name}: {key}")
        assert (taken.solver is None) == (own.solver is None)
        if own.solver is not None:
            for field in ("objective_kw", "solver_status", "fallback", "certified_by", "iterations"):
                np.testing.assert_array_equal(
                    getattr(taken.solver, field), getattr(own.solver, field), err_msg=f"{name}: {field}"
                )
