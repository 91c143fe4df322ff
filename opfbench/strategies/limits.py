"""The reactive bound ±L (MVAr) that LLMA and LFMA apply to every setpoint.

L = (1 − k)·Qmax(P^C) without a forecast. With a forecast (Algorithm 3) the capability
is evaluated at both the forecast P^F and the current P^C and the larger one is used:
L = (1 − k)·max(Qmax(P^F), Qmax(P^C)) — active power itself stays at P^C, so L may
exceed the physical capability Qmax(P^C). `safe=True` caps L at Qmax(P^C).

The paper phrases Algorithm 3 as "use P^F if it gives the larger setpoint"; for the
positive (capacitive) setpoints the rules produce when loads are inductive that is the
same as using the larger limit, which is what is done here for every sign.
"""

from __future__ import annotations

import numpy as np

from opfbench.capability import check_reserve
from opfbench.scenario import Scenario


def physical_limit(scenario: Scenario) -> np.ndarray:
    """(S, n_der) MVAr: each DER's capability Qmax at its current active power P^C."""
    return scenario.qmax_mvar()


def reactive_limit(scenario: Scenario, k: float, safe: bool = False) -> np.ndarray:
    """(S, n_der) MVAr: the bound L ≥ 0 of |Q| for the local rules (see module docstring)."""
    now = physical_limit(scenario)
    capability = now
    if scenario.der_p_forecast_mw is not None:
        capability = np.maximum(now, scenario.qmax_mvar(scenario.der_p_forecast_mw))
    limit = (1.0 - check_reserve(k)) * capability
    return np.minimum(limit, now) if safe else limit


def clip(target_mvar: np.ndarray, limit_mvar: np.ndarray) -> np.ndarray:
    """Setpoint = target clipped to [−L, L] (MVAr); min(target, L) for the usual positive
    target, as in the paper's formulas. Returns +0.0 rather than −0.0 when L = 0."""
    return np.clip(target_mvar, -limit_mvar, limit_mvar) + 0.0
