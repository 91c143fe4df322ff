"""The bounds every local rule's setpoints pass through: the reactive bound ±L (MVAr) that
LLMA and LFMA apply, and — where a rule caps its active power (Volt-Watt) or gives Q
priority — the active power each DER delivers.

L = (1 − k)·Qmax(P^C) without a forecast. With a forecast (Algorithm 3) the capability
is evaluated at both the forecast P^F and the current P^C and the larger one is used:
L = (1 − k)·max(Qmax(P^F), Qmax(P^C)) — active power itself stays at P^C, so L may
exceed the physical capability Qmax(P^C). `safe=True` caps L at Qmax(P^C).

The paper phrases Algorithm 3 as "use P^F if it gives the larger setpoint"; for the
positive (capacitive) setpoints the rules produce when loads are inductive that is the
same as using the larger limit, which is what is done here for every sign.

Active power (`Capability.setpoints`): a DER delivers its available power P^C, or less
where the rule caps it (P ≤ cap, only positive output is curtailed). Under active-power
priority (`priority="p"`, the default, IEEE 1547-2018's and OpenDSS's default) the
delivered power comes first and L is evaluated at it (curtailing frees room on the S̄
circle). Under reactive priority (`priority="q"`) the capability is the peak a unit
reaches by curtailing (`capability.q_peak`) and the unit then delivers the largest power
at which (1 − k)·Qmax still covers its Q (`capability.p_for_q`). Curtailed power is
P^C minus the delivered power.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from opfbench.capability import check_reserve, p_for_q, q_peak, qmax
from opfbench.scenario import Scenario
from opfbench.strategies.rules import PRIORITIES


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


@dataclass(frozen=True, eq=False)
class Capability:
    """A scenario's DER as the bounds of a rule's setpoints (module docstring), at reserve
    k, Algorithm 3's limit capped where `safe`, with priority "p" or "q"."""

    scenario: Scenario
    k: float
    safe: bool = False
    priority: str = "p"
    _fixed: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        object.__setattr__(self, "k", check_reserve(self.k))
        if self.priority not in PRIORITIES:
            raise ValueError(f"priority must be one of {PRIORITIES}, got {self.priority!r}")
        fixed = reactive_limit(self.scenario, self.k, self.safe) if self.priority == "p" else None
        object.__setattr__(self, "_fixed", fixed)  # L where the DER deliver P^C (priority p)

    def _curve(self, rows: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """The capability (MVAr) of the DER at snapshots `rows` as a function of their power."""
        sc, net = self.scenario, self.scenario.net
        night = sc.night_q()
        night_rows = night[rows] if isinstance(night, np.ndarray) else False
        curve = qmax if self.priority == "p" else q_peak
        return lambda p: curve(net.der_kinds, p, net.der_rating_mw, net.der_s_mva, night_rows)

    def limit(self, rows: np.ndarray, p_mw: np.ndarray | None = None) -> np.ndarray:
        """(rows, n_der) MVAr: L at snapshots `rows`, the DER delivering `p_mw` (default P^C)."""
        if p_mw is None and self._fixed is not None:
            return self._fixed[rows]
        sc = self.scenario
        curve = self._curve(rows)
        now = curve(sc.der_p_mw[rows] if p_mw is None else p_mw)
        capability = now if sc.der_p_forecast_mw is None else np.maximum(now, curve(sc.der_p_forecast_mw[rows]))
        limit = (1.0 - self.k) * capability
        return np.minimum(limit, now) if self.safe else limit

    def setpoints(self, rows: np.ndarray, q_target: np.ndarray, p_cap: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """(Q, P) at snapshots `rows` for Q targets (MVAr) and active-power caps (MW, None:
        none); P is None where every DER delivers P^C (module docstring)."""
        if p_cap is None and self.priority == "p":
            return clip(q_target, self.limit(rows)), None
        available = self.scenario.der_p_mw[rows]
        top = available if p_cap is None else np.where(available > 0, np.minimum(available, np.maximum(p_cap, 0.0)), available)
        q = clip(q_target, self.limit(rows, top))
        if self.priority == "p":
            return q, top
        net, night = self.scenario.net, self.scenario.night_q()
        night_rows = night[rows] if isinstance(night, np.ndarray) else False
        return q, p_for_q(net.der_kinds, q, top, net.der_rating_mw, net.der_s_mva, night_rows, 1.0 - self.k)
