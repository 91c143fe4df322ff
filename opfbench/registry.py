"""Name → runner for every strategy. A runner is `run(scenario, k, **options) ->
StrategyResult` over all snapshots of the scenario; local rules live in
`opfbench.strategies`, centralized formulations in `opfbench.formulations`."""

from __future__ import annotations

import importlib
from typing import Callable

from opfbench.errors import InputError
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario

Runner = Callable[..., StrategyResult]

LOCAL_RULES = ("no-action", "llma", "lfma")
FORMULATIONS = ("acopf", "socp")
_RUNNERS = {
    "no-action": "opfbench.strategies.local:no_action",
    "llma": "opfbench.strategies.local:llma",
    "lfma": "opfbench.strategies.local:lfma",
    "acopf": "opfbench.formulations.acopf:run_acopf",
    "socp": "opfbench.formulations.socp:run_socp",
}
STRATEGY_NAMES = tuple(_RUNNERS)


def get_runner(name: str) -> Runner:
    if name not in _RUNNERS:
        raise InputError(f"unknown strategy {name!r}; choose from {', '.join(STRATEGY_NAMES)}")
    module, func = _RUNNERS[name].split(":")
    return getattr(importlib.import_module(module), func)


def run_strategy(name: str, scenario: Scenario, k: float, **options) -> StrategyResult:
    return get_runner(name)(scenario, k, **options)
