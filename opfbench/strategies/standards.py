"""The reactive-power rules grid codes mandate, as targets of the local-rule engine
(`opfbench.strategies.rule_engine`: every target then passes through the (1 − k)·Qmax limits,
Algorithm 3 and the night modes, and rules of |V| are solved for their closed-loop steady
state).

Sign convention: Q positive = injected (over-excited, capacitive behaviour); a target in
"p.u. of S̄" is Q / S̄ with S̄ the DER's nameplate apparent power (`Network.der_s_mva`;
S̄ = P̄ for the paper's PV and DFIG units). The VDE application rules use the consumer
reference-arrow system (Verbraucherzählpfeilsystem), in which an under-excited generator
— one that absorbs reactive power, behaving like an inductor — has Q > 0; here that is
Q < 0, and every VDE figure below is converted to our generator sign.

- `volt-var`: IEEE 1547-2018 Volt-VAR Q(V), piecewise linear in own-bus |V| and flat
  beyond its end points; Category B (default) (0.92, +0.44), (0.98, 0), (1.02, 0),
  (1.08, −0.44) and Category A (0.90, +0.25), (1.00, 0), (1.10, −0.25), in p.u. of S̄.
- `watt-var`: IEEE 1547-2018 Watt-VAR Q(P), P in p.u. of P̄: (0.2, 0), (0.5, 0),
  (1.0, −0.44) for Category B, −0.25 for Category A, in p.u. of S̄.
- `volt-watt`: IEEE 1547-2018 Volt-Watt P(V), a cap on active power in p.u. of P̄ (OpenDSS
  `VoltwattYAxis=PMPPPU`), piecewise linear in own-bus |V| and flat beyond its ends:
  (1.06, 1.0), (1.10, 0.0) — the default of Categories A and B (P2 the lesser of 0.2·P̄
  and the unit's minimum output, 0 for an inverter); Q stays 0.
- `volt-var+volt-watt`: both at once, as OpenDSS's `CombiMode=VV_VW`: Q from the Volt-VAR
  curve, P capped by the Volt-Watt curve.
- `const-pf`: constant power factor, Q = ∓|P|·tan(acos pf) (absorb: −, inject: +).
- `cosphi-p`: VDE-AR-N 4105 cos φ(P): cos φ = 1 up to P/P̄ = 0.5, then linear down to
  0.90 under-excited (absorbing) at P̄; 0.95 for units of at most 4.6 kVA.
- `q-u`: VDE-AR-N 4110 Q(U): (0.96, +0.33), (1.04, −0.33) in p.u. of P̄ (the VDE's
  reference for Q), or with a dead band (0.94, +0.33), (0.96, 0), (1.04, 0), (1.06, −0.33).

Each `check_*` refuses options a rule cannot mean (curve voltages not increasing, |Q| > 1
p.u., pf outside (0, 1], …) with one message naming the option.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from opfbench.errors import InputError
from opfbench.registry.options import Option
from opfbench.strategies.registration import local_rule
from opfbench.strategies.rules import Measurements, Targets

Points = tuple[tuple[float, ...], tuple[float, ...]]

VOLT_VAR: dict[str, Points] = {
    "a": ((0.90, 1.00, 1.10), (0.25, 0.0, -0.25)),
    "b": ((0.92, 0.98, 1.02, 1.08), (0.44, 0.0, 0.0, -0.44)),
}
WATT_VAR: dict[str, Points] = {
    "a": ((0.2, 0.5, 1.0), (0.0, 0.0, -0.25)),
    "b": ((0.2, 0.5, 1.0), (0.0, 0.0, -0.44)),
}
VOLT_WATT: Points = ((1.06, 1.10), (1.0, 0.0))
Q_U_V = (0.96, 1.04)
Q_U_DEADBAND_V = (0.94, 0.96, 1.04, 1.06)
Q_U_MAX = 0.33  # p.u. of P̄
COSPHI_P_START = 0.5  # P/P̄ where cos φ(P) leaves 1
COSPHI_P_MIN = 0.90  # cos φ at P̄ (units above 4.6 kVA); 0.95 for smaller ones
PF = 0.95


CURVE = Option("curve", "b", "IEEE 1547-2018 category: a or b", choices=("a", "b"))


def curve_points(x: str, help_x: str) -> tuple[Option, Option]:
    """The options of a curve's explicit points: `x` (the abscissae, described by `help_x`) and q."""
    return (
        Option(x, (), f"explicit curve points instead of a preset: {help_x}, increasing, written 0.9/1.0/1.1 (with q=)"),
        Option("q", (), "explicit curve points: Q per unit, one per point, written 0.44/0/-0.44"),
    )


def piecewise(points: Points, x: np.ndarray) -> np.ndarray:
    """The piecewise-linear curve through `points` at x, flat beyond its end points."""
    return np.interp(x, points[0], points[1])


def _points(x: Sequence[float], y: Sequence[float], preset: Points) -> Points:
    """Explicit points (x, y) where both are given, else the preset."""
    return (tuple(x), tuple(y)) if x else preset


def check_points(
    rule: str, x_name: str, x: Sequence[float], y: Sequence[float], x_range: tuple[float, float], y_name: str = "q"
) -> None:
    """Explicit curve points: x and y given together, equally many (≥ 2), x strictly
    increasing inside `x_range`, |y| ≤ 1 p.u."""
    if bool(x) != bool(y):
        raise InputError(f"{rule}: give both {x_name}= and {y_name}= (the curve's points), or neither")
    if not x:
        return
    if len(x) != len(y) or len(x) < 2:
        raise InputError(f"{rule}: {x_name}= and {y_name}= need the same number of points, at least 2; got {len(x)} and {len(y)}")
    if any(b <= a for a, b in zip(x[:-1], x[1:], strict=True)):
        raise InputError(f"{rule}: the curve's {x_name} values must increase, got {'/'.join(f'{v:g}' for v in x)}")
    lo, hi = x_range
    if not all(lo <= v <= hi for v in x):
        raise InputError(f"{rule}: the curve's {x_name} values must lie in [{lo:g}, {hi:g}], got {'/'.join(f'{v:g}' for v in x)}")
    if any(abs(v) > 1 for v in y):
        raise InputError(
            f"{rule}: the curve's {y_name.upper()} values are per unit and must lie in [−1, 1], got "
            f"{'/'.join(f'{v:g}' for v in y)}"
        )


def check_pf(rule: str, pf: float) -> None:
    if not 0 < pf <= 1:
        raise InputError(f"{rule}: a power factor must lie in (0, 1], got {pf:g}")


# ----- IEEE 1547-2018 ---------------------------------------------------------------------
def check_preset_or_points(rule: str, options: dict, x_name: str) -> None:
    """A category other than the default and explicit points are two curves: refused."""
    if options["curve"] != "b" and options[x_name]:
        raise InputError(f"{rule}: give curve= or the points {x_name}=/q=, not both")


def check_volt_var(options: dict) -> None:
    check_preset_or_points("volt-var", options, "v")
    check_points("volt-var", "v", options["v"], options["q"], (0.5, 1.5))


@local_rule(
    "volt-var",
    reads=("v",),
    options=(CURVE, *curve_points("v", "|V| p.u.")),
    summary="IEEE 1547-2018 Volt-VAR Q(V) in p.u. of S̄ (B: 0.92/+0.44 0.98/0 1.02/0 1.08/−0.44; "
    "A: 0.90/+0.25 1.00/0 1.10/−0.25), closed loop",
    check=check_volt_var,
    snapshot_wise=True,
)
def volt_var(m: Measurements, curve: str = "b", v: Sequence[float] = (), q: Sequence[float] = ()) -> np.ndarray:
    """Volt-VAR: Q(|V|) in p.u. of S̄ (Category `curve`, or the points v/q), MVAr."""
    return piecewise(_points(v, q, VOLT_VAR[curve]), m.v_pu) * m.s_rated_mva


def check_watt_var(options: dict) -> None:
    check_preset_or_points("watt-var", options, "p")
    check_points("watt-var", "p", options["p"], options["q"], (0.0, 1.0))


@local_rule(
    "watt-var",
    reads=("p",),
    options=(CURVE, *curve_points("p", "P/P̄")),
    summary="IEEE 1547-2018 Watt-VAR Q(P/P̄) in p.u. of S̄ (0.2/0 0.5/0 1.0/−0.44 for B, −0.25 for A)",
    check=check_watt_var,
    snapshot_wise=True,
)
def watt_var(m: Measurements, curve: str = "b", p: Sequence[float] = (), q: Sequence[float] = ()) -> np.ndarray:
    """Watt-VAR: Q(P/P̄) in p.u. of S̄ (Category `curve`, or the points p/q), MVAr."""
    return piecewise(_points(p, q, WATT_VAR[curve]), m.p_mw / m.p_rated_mw) * m.s_rated_mva


def watt_points(v: str, p: str) -> tuple[Option, Option]:
    """The options of a Volt-Watt curve's explicit points: voltages `v` and caps `p`."""
    return (
        Option(
            v, (), f"Volt-Watt curve points instead of IEEE 1547's default: |V| p.u., increasing, written 1.06/1.1 (with {p}=)"
        ),
        Option(p, (), "Volt-Watt curve points: the active-power cap in p.u. of P̄, one per point, not increasing, written 1/0"),
    )


def volt_watt_cap(m: Measurements, v: Sequence[float] = (), p: Sequence[float] = ()) -> np.ndarray:
    """The Volt-Watt cap on active power: P(|V|) in p.u. of P̄ (the default curve, or the
    points v/p), MW."""
    return piecewise(_points(v, p, VOLT_WATT), m.v_pu) * m.p_rated_mw


def check_volt_watt_points(rule: str, v: Sequence[float], p: Sequence[float], v_name: str = "v", p_name: str = "p") -> None:
    """A Volt-Watt curve: points as `check_points`, P in [0, 1] p.u. of P̄ and non-increasing
    (a cap that rises with |V| would push the voltage up further)."""
    check_points(rule, v_name, v, p, (0.5, 1.5), p_name)
    if any(y < 0 for y in p) or any(b > a for a, b in zip(p[:-1], p[1:], strict=False)):
        raise InputError(
            f"{rule}: the Volt-Watt curve's {p_name} values must lie in [0, 1] and not increase, got "
            f"{'/'.join(f'{y:g}' for y in p)}"
        )


def check_volt_watt(options: dict) -> None:
    check_volt_watt_points("volt-watt", options["v"], options["p"])


@local_rule(
    "volt-watt",
    reads=("v",),
    options=watt_points("v", "p"),
    summary="IEEE 1547-2018 Volt-Watt: active power capped at P(V) in p.u. of P̄ (1.06/1 1.10/0), Q = 0, closed loop",
    check=check_volt_watt,
    curtails=True,
    snapshot_wise=True,
)
def volt_watt(m: Measurements, v: Sequence[float] = (), p: Sequence[float] = ()) -> Targets:
    """Volt-Watt: active power capped at P(|V|) (`volt_watt_cap`), Q target 0."""
    return Targets(np.zeros(m.shape), volt_watt_cap(m, v, p))


def check_volt_var_volt_watt(options: dict) -> None:
    check_preset_or_points("volt-var+volt-watt", options, "v")
    check_points("volt-var+volt-watt", "v", options["v"], options["q"], (0.5, 1.5))
    check_volt_watt_points("volt-var+volt-watt", options["vw_v"], options["vw_p"], "vw_v", "vw_p")


@local_rule(
    "volt-var+volt-watt",
    reads=("v",),
    options=(CURVE, *curve_points("v", "|V| p.u."), *watt_points("vw_v", "vw_p")),
    summary="IEEE 1547-2018 Volt-VAR and Volt-Watt together (OpenDSS CombiMode=VV_VW), closed loop",
    check=check_volt_var_volt_watt,
    curtails=True,
    snapshot_wise=True,
)
def volt_var_volt_watt(
    m: Measurements,
    curve: str = "b",
    v: Sequence[float] = (),
    q: Sequence[float] = (),
    vw_v: Sequence[float] = (),
    vw_p: Sequence[float] = (),
) -> Targets:
    """Volt-VAR and Volt-Watt together (OpenDSS `CombiMode=VV_VW`): the Q target of
    `volt_var` and the P cap of `volt_watt_cap` (points vw_v/vw_p)."""
    return Targets(volt_var(m, curve, v, q), volt_watt_cap(m, vw_v, vw_p))


# ----- power factor -----------------------------------------------------------------------
def check_const_pf(options: dict) -> None:
    check_pf("const-pf", options["pf"])


@local_rule(
    "const-pf",
    reads=("p",),
    options=(
        Option("pf", PF, "power factor in (0, 1]"),
        Option("mode", "absorb", "absorb (under-excited) or inject (over-excited)", choices=("absorb", "inject")),
    ),
    summary="constant power factor: Q = ∓|P|·tan(acos pf)",
    check=check_const_pf,
    snapshot_wise=True,
)
def const_pf(m: Measurements, pf: float = PF, mode: str = "absorb") -> np.ndarray:
    """Constant power factor: Q = −|P|·tan(acos pf) absorbing, +|P|·tan(acos pf) injecting, MVAr."""
    sign = -1.0 if mode == "absorb" else 1.0
    return sign * np.abs(m.p_mw) * np.tan(np.arccos(pf))


def check_cosphi_p(options: dict) -> None:
    check_pf("cosphi-p", options["pf_min"])
    if not 0 <= options["p_start"] < 1:
        raise InputError(f"cosphi-p: p_start is a share of P̄ in [0, 1), got {options['p_start']:g}")


@local_rule(
    "cosphi-p",
    reads=("p",),
    options=(
        Option("pf_min", COSPHI_P_MIN, "cos φ at P̄, under-excited (0.95 for units ≤ 4.6 kVA)"),
        Option("p_start", COSPHI_P_START, "P/P̄ where cos φ leaves 1"),
    ),
    summary="VDE-AR-N 4105 cos φ(P): 1 up to P/P̄ = 0.5, then linear to 0.90 under-excited at P̄",
    check=check_cosphi_p,
    snapshot_wise=True,
)
def cosphi_p(m: Measurements, pf_min: float = COSPHI_P_MIN, p_start: float = COSPHI_P_START) -> np.ndarray:
    """VDE-AR-N 4105 cos φ(P): cos φ = 1 up to P/P̄ = p_start, then linear to pf_min
    under-excited at P̄; Q = −|P|·tan(acos cos φ) MVAr (absorbing; the VDE's consumer sign
    would have it positive)."""
    cos_phi = piecewise(((p_start, 1.0), (1.0, pf_min)), m.p_mw / m.p_rated_mw)
    return -np.abs(m.p_mw) * np.tan(np.arccos(cos_phi))


# ----- VDE-AR-N 4110 ------------------------------------------------------------------------
def check_q_u(options: dict) -> None:
    preset = [key for key, default in (("deadband", False), ("q_max", Q_U_MAX)) if options[key] != default]
    if preset and options["v"]:
        raise InputError(
            f"q-u: give {'= or '.join(preset)}= (the characteristic) or the points v=/q=, not both: the points replace it"
        )
    if not 0 <= options["q_max"] <= 1:
        raise InputError(f"q-u: q_max is per unit of P̄ and must lie in [0, 1], got {options['q_max']:g}")
    check_points("q-u", "v", options["v"], options["q"], (0.5, 1.5))


@local_rule(
    "q-u",
    reads=("v",),
    options=(
        Option("deadband", False, "the characteristic with its dead band 0.96–1.04 p.u."),
        Option("q_max", Q_U_MAX, "Q at the characteristic's ends, p.u. of P̄"),
        *curve_points("v", "|V| p.u."),
    ),
    summary="VDE-AR-N 4110 Q(U): 0.96/+0.33 to 1.04/−0.33 p.u. of P̄ (dead band: 0.94/0.96/1.04/1.06), closed loop",
    check=check_q_u,
    snapshot_wise=True,
)
def q_u(
    m: Measurements, deadband: bool = False, q_max: float = Q_U_MAX, v: Sequence[float] = (), q: Sequence[float] = ()
) -> np.ndarray:
    """Q(U): ±q_max p.u. of P̄ at the ends of the characteristic (with or without its dead
    band), or the explicit points v/q (p.u. of P̄), MVAr; positive (injecting) below 1 p.u."""
    preset = (Q_U_DEADBAND_V, (q_max, 0.0, 0.0, -q_max)) if deadband else (Q_U_V, (q_max, -q_max))
    return piecewise(_points(v, q, preset), m.v_pu) * m.p_rated_mw
