"""Every registered strategy runs through the one registry and returns the one record."""

import numpy as np
import pytest

from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.registry import FORMULATIONS, LOCAL_RULES, STRATEGIES, STRATEGY_NAMES, get_strategy, run_strategy
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario


def test_registry_partitions_strategies():
    assert set(LOCAL_RULES) | set(FORMULATIONS) == set(STRATEGY_NAMES)
    assert not set(LOCAL_RULES) & set(FORMULATIONS)
    assert {"no-action", "llma", "lfma", "acopf", "acopf-paper", "socp"} <= set(STRATEGY_NAMES)


@pytest.mark.parametrize("name", STRATEGY_NAMES)
def test_every_registered_strategy_returns_the_record(name):
    net = load_network("paper33")
    scenario = Scenario.snapshot(net, 1.0, 0.8, 0.9 if STRATEGIES[name].uses_forecast else None)
    res = run_strategy(name, scenario, 0.2)
    assert isinstance(res, StrategyResult)
    assert res.strategy == name and res.k == 0.2
    assert res.q_mvar.shape == (1, len(net.ders))
    assert res.status[0] == "ok" and np.isfinite(res.losses_kw[0])
    assert res.losses_kw[0] <= 84.26 + 1e-3  # never worse than no action's 84.260 kW (pandapower-checked)
    assert res.snapshot_json(0)["strategy"] == name


def test_acopf_paper_pins_the_papers_setup():
    spec = get_strategy("acopf-paper")
    assert spec.fixed == {"fallback": "paper", "slack_export": False}
    assert spec.options == {"solver": "auto"}  # the fast path, or IPOPT on every step
    res = run_strategy("acopf-paper", Scenario.snapshot(load_network("paper33")), 0.0)
    assert res.extra["slack_export"] is False


def test_unknown_strategy_and_option_are_input_errors():
    scenario = Scenario.snapshot(load_network("paper33"))
    with pytest.raises(InputError, match="unknown strategy 'nope'"):
        run_strategy("nope", scenario, 0.0)
    with pytest.raises(InputError, match="takes no option safe"):
        run_strategy("acopf", scenario, 0.0, safe=True)
    with pytest.raises(InputError, match="takes no option fallback"):
        run_strategy("acopf-paper", scenario, 0.0, fallback="chain")
