"""What a local rule is: a function of the DER's own measurements (`Measurements`) giving
its Q target, and what it reads (`Rule.reads`); the engine that runs rules is
`opfbench.strategies.rule_engine`. Light to import (numpy only): the registry and the CLI use it.

A rule's answer is each DER's Q target, or — a rule that also limits active power, as
IEEE 1547's Volt-Watt does — `Targets`: the Q targets and a cap on each DER's active power
(the rule must declare that it curtails, `Rule.curtails`).

Units: |V| p.u.; P in MW, Q in MVAr, positive = injected by the DER (loads: positive =
consumed; lines: positive = leaving the DER's bus into the line). The active power a rule
reads ("p") is the DER's available power P^C, whatever it curtails.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from opfbench.errors import InputError

#: What a rule may read (`Rule.reads`): own-bus |V|, own P^C, own forecast P^F, own-bus
#: load, the power on the incident lines.
READS = ("v", "p", "p_forecast", "load", "flows")
#: Measured quantities the DER's own Q changes: a rule reading one is closed-loop.
FEEDBACK = frozenset({"v", "flows"})
RESIDUAL = "residual_mvar"
#: An inverter's priority where its capability binds: active (p) or reactive (q) power
#: (`limits.Capability`).
PRIORITIES = ("p", "q")


@dataclass(frozen=True)
class Settling:
    """The closed-loop iteration's parameters: at most `max_steps` damped steps; settled at
    max|ΔQ| ≤ tol_q_mvar (MVAr) and max|ΔV| ≤ tol_v_pu (p.u.); step factor α starting at
    `step_factor`, adapted (OpenDSS InvControl) when `adaptive`, else fixed (1 = undamped)."""

    max_steps: int = 100
    tol_v_pu: float = 1e-7
    tol_q_mvar: float = 1e-7
    step_factor: float = 0.5
    adaptive: bool = True


DEFAULT_SETTLING = Settling()


class Measurements:
    """What every DER measures at its own bus, for the rows (snapshots) being evaluated.
    Arrays are (S, n_der) unless noted; only what the rule declares it reads is there
    (reading anything else is an InputError naming it).

    v_pu ("v"): own-bus |V|, p.u. · p_mw ("p"): own active power P^C, MW · p_forecast_mw
    ("p_forecast"): forecast P^F, MW (P^C where the scenario has none) · load_p_mw,
    load_q_mvar ("load"): the DER's share of its bus's load, MW / MVAr, positive = consumed
    (`bus_share` × the bus's: several DER at one bus share it) · line_mva ("flows"):
    (S, n_der, m) complex MVA leaving the bus into each incident line (P + jQ; 0 in
    padding, see `line_valid` (n_der, m)) — the bus's meters, the same for every DER at the
    bus: a rule that compensates a flow takes its `bus_share` of it. Always there: shape
    (S, n_der), s_rated_mva (n_der,) nameplate S̄, p_rated_mw (n_der,) rating P̄, kinds
    (n_der,) DER kinds, bus_share (n_der,) the DER's share of its bus, S̄ / Σ S̄ of the DER
    there (1 for a DER alone).
    """

    def __init__(
        self,
        reads: frozenset[str],
        values: dict[str, np.ndarray],
        n_rows: int,
        s_rated_mva: np.ndarray,
        p_rated_mw: np.ndarray,
        kinds: np.ndarray,
        line_valid: np.ndarray,
        bus_share: np.ndarray | None = None,
    ) -> None:
        self.reads = reads
        self.shape = (n_rows, len(s_rated_mva))
        self._values = values
        self.s_rated_mva = s_rated_mva
        self.p_rated_mw = p_rated_mw
        self.kinds = kinds
        self.line_valid = line_valid
        self.bus_share = np.ones(len(s_rated_mva)) if bus_share is None else bus_share

    def _get(self, read: str, field: str) -> np.ndarray:
        if read not in self.reads:
            raise InputError(f"the rule reads {field} but does not declare {read!r} in what it reads ({', '.join(READS)})")
        return self._values[field]

    @property
    def v_pu(self) -> np.ndarray:
        return self._get("v", "v_pu")

    @property
    def p_mw(self) -> np.ndarray:
        return self._get("p", "p_mw")

    @property
    def p_forecast_mw(self) -> np.ndarray:
        return self._get("p_forecast", "p_forecast_mw")

    @property
    def load_p_mw(self) -> np.ndarray:
        return self._get("load", "load_p_mw")

    @property
    def load_q_mvar(self) -> np.ndarray:
        return self._get("load", "load_q_mvar")

    @property
    def line_mva(self) -> np.ndarray:
        return self._get("flows", "line_mva")


@dataclass(frozen=True)
class Targets:
    """What a rule asks of each DER (S, n_der): `q_mvar` its Q target, MVAr; `p_max_mw` a
    cap on its active power, MW (None: none — it delivers its available power)."""

    q_mvar: np.ndarray
    p_max_mw: np.ndarray | None = None

    @property
    def finite(self) -> np.ndarray:
        """(S,) whether every DER's answer at the snapshot is finite."""
        ok = np.isfinite(self.q_mvar).all(axis=1)
        return ok if self.p_max_mw is None else ok & np.isfinite(self.p_max_mw).all(axis=1)


Target = Callable[..., "np.ndarray | Targets"]


@dataclass(frozen=True)
class Rule:
    """A local rule: `target(m, **options)` → (S, n_der) Q target in MVAr (positive =
    injected), or `Targets` where it `curtails` (caps active power); reading `reads` ⊆
    READS; `name` labels its messages."""

    name: str
    target: Target
    reads: frozenset[str]
    curtails: bool = False

    @property
    def closed_loop(self) -> bool:
        return bool(self.reads & FEEDBACK)


def _real(rule: Rule, values: object, should: str) -> np.ndarray:
    """`values` as floats; InputError (`should`: what they must be) unless they are real
    numbers (complex: its imaginary part would be dropped; text, objects)."""
    arr = np.asarray(values)
    if arr.dtype.kind not in "biuf":
        raise InputError(f"rule {rule.name!r} returned {arr.dtype} values; {should}")
    return arr.astype(float)


def targets(rule: Rule, m: Measurements, options: dict, n_rows: int) -> Targets:
    """The rule's targets (rows, n_der): Q (MVAr) and, for a rule that curtails, a cap on
    active power (MW); InputError naming the rule for an exception (a `sys.exit` too), an
    answer that is not real numbers (complex included), a wrong shape or a cap on active
    power from a rule that does not declare it curtails (non-finite values are the
    caller's to handle)."""
    n_der = m.shape[1]
    try:
        raw = rule.target(m, **options)
        answer = raw if isinstance(raw, Targets) else Targets(raw)
        caps = None if answer.p_max_mw is None else _real(rule, answer.p_max_mw, "a cap on active power is real numbers (MW)")
        out = Targets(_real(rule, answer.q_mvar, "a Q target is real numbers (MVAr)"), caps)
    except InputError:
        raise
    except (Exception, SystemExit) as exc:  # a rule's own bug, or its sys.exit: named, never a traceback or an exit
        raise InputError(f"rule {rule.name!r} failed: {type(exc).__name__}: {exc}") from None
    for what, arr in (("", out.q_mvar), (" active-power caps of", out.p_max_mw)):
        if arr is not None and arr.shape != (n_rows, n_der):
            raise InputError(
                f"rule {rule.name!r} returned{what} shape {arr.shape}; it must return (S, n_der) = ({n_rows}, {n_der})"
            )
    if out.p_max_mw is not None and not rule.curtails:
        raise InputError(f"rule {rule.name!r} caps active power but is not declared a rule that curtails")
    return out
