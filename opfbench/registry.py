"""Every strategy described once: its kind (local rule or centralized formulation), the
function that runs it, the options a caller may set and the fixed options of this entry,
and whether it reads a forecast (Algorithm 3). `opfbench snapshot`, the local-rule table,
the study runner and the benchmarks read this table; nothing else lists strategies.

A runner is `run(scenario, k, **options) -> StrategyResult` over all snapshots of the
scenario; local rules live in `opfbench.strategies`, formulations in
`opfbench.formulations`. An entry may pin options of its function: `acopf-paper` is the
AC OPF under the paper's setup (the slack may not export, a failed solve falls back to
no action), a configuration of its own in the benchmark grid.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Literal

import numpy as np

from opfbench.errors import InputError

if TYPE_CHECKING:
    from opfbench.result import StrategyResult
    from opfbench.scenario import Scenario

Runner = Callable[..., "StrategyResult"]
Kind = Literal["local", "formulation"]


@dataclass(frozen=True)
class StrategySpec:
    """One registered strategy. `target` is "module:function"; `options` the keyword
    options a caller may set (with their defaults); `fixed` options this entry pins;
    `uses_forecast`: the result depends on the scenario's forecast P^F."""

    name: str
    kind: Kind
    target: str
    summary: str
    options: dict[str, object] = field(default_factory=dict)
    fixed: dict[str, object] = field(default_factory=dict)
    uses_forecast: bool = False

    @property
    def runner(self) -> Runner:
        module, func = self.target.split(":")
        return getattr(importlib.import_module(module), func)

    def run(self, scenario: Scenario, k: float, **options) -> StrategyResult:
        """Run on every snapshot of `scenario`; the result carries this entry's name.
        InputError for a scenario that is not a `Scenario`, a k that is not one real
        number (text, true/false), an unknown option or one not of its default's type."""
        from opfbench.scenario import Scenario

        if not isinstance(scenario, Scenario):
            raise InputError(
                f"strategy {self.name!r} runs on a Scenario (e.g. Scenario.snapshot(net)), got {type(scenario).__name__}"
            )
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, float, np.number, np.ndarray)):
            raise InputError(f"reserve coefficient k must be a number in [0, 1], got {k!r}")
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            allowed = ", ".join(self.options) or "none"
            raise InputError(f"strategy {self.name!r} takes no option {', '.join(unknown)} (options: {allowed})")
        for key, value in options.items():  # of the default's type: 'false' is not False
            default = self.options[key]
            kind = (bool, np.bool_) if isinstance(default, bool) else type(default)
            if not isinstance(value, kind):
                raise InputError(
                    f"strategy {self.name!r}: option {key} must be a {type(default).__name__} like its default "
                    f"{default!r}, got {value!r}"
                )
        result = self.runner(scenario, k, **(self.options | options | self.fixed))
        return result if result.strategy == self.name else dataclasses.replace(result, strategy=self.name)


STRATEGIES: dict[str, StrategySpec] = {
    s.name: s
    for s in (
        StrategySpec("no-action", "local", "opfbench.strategies.paper:no_action", "every DER at Q = 0"),
        StrategySpec(
            "llma",
            "local",
            "opfbench.strategies.paper:llma",
            "Algorithm 1: Q = the load's Q at the DER's own bus, within (1 − k)·Qmax",
            options={"safe": False},
            uses_forecast=True,
        ),
        StrategySpec(
            "lfma",
            "local",
            "opfbench.strategies.paper:lfma",
            "Algorithm 2: LLMA plus the measured upstream Q inflow, sign-change rules",
            options={"safe": False},
            uses_forecast=True,
        ),
        StrategySpec(
            "acopf",
            "formulation",
            "opfbench.formulations.acopf:run_acopf",
            "centralized AC OPF (IPOPT), fallback chain ending at an AC-feasible point",
            options={"fallback": "chain", "slack_export": True, "solver": "auto"},
        ),
        StrategySpec(
            "acopf-paper",
            "formulation",
            "opfbench.formulations.acopf:run_acopf",
            "AC OPF under the paper's setup: slack may not export, failure → no action",
            options={"solver": "auto"},
            fixed={"fallback": "paper", "slack_export": False},
        ),
        StrategySpec(
            "socp",
            "formulation",
            "opfbench.formulations.socp:run_socp",
            "SOCP relaxation (Clarabel): certified lower bound; its Q evaluated by AC power flow",
            options={"slack_export": True},
        ),
    )
}
STRATEGY_NAMES = tuple(STRATEGIES)
#: The reference configurations every comparison is made against: the baseline (every DER
#: at Q = 0) and the optimum whose loss reduction the others' shares are measured by.
BASELINE = "no-action"
REFERENCE_OPTIMUM = "acopf"
LOCAL_RULES = tuple(n for n, s in STRATEGIES.items() if s.kind == "local")
FORMULATIONS = tuple(n for n, s in STRATEGIES.items() if s.kind == "formulation")


def get_strategy(name: str) -> StrategySpec:
    if name not in STRATEGIES:
        raise InputError(f"unknown strategy {name!r}; choose from {', '.join(STRATEGY_NAMES)}")
    return STRATEGIES[name]


def run_strategy(name: str, scenario: Scenario, k: float, **options) -> StrategyResult:
    """Run the registered strategy `name` (see `StrategySpec.run`)."""
    return get_strategy(name).run(scenario, k, **options)
