"""DER reactive capability (paper §III). All quantities in MW/MVAr; Q positive =
injected (over-excited). Limits are symmetric: Qmin = −Qmax.

- PV (the paper's): |Q| ≤ P·tan(acos 0.8) = 0.75·P and |Q| ≤ √(S̄² − P²) (S̄ = P̄ unless
  the unit's nameplate says more).
- DFIG: piecewise-linear in p = P/P̄: Qmax/P̄ = 1 for p ≤ 0.4; −5/6·p + 4/3 for 0.4 < p < 1;
  0.5 at p = 1.
- inverter (a generic inverter-coupled unit: the PV, wind, biomass and hydro static
  generators of real grids): |Q| ≤ |P|·tan(acos 0.90) and |Q| ≤ √(S̄² − P²). The power
  factor range cos φ 0.90 under- to over-excited is the one VDE-AR-N 4105:2018-11 (§5.7.2,
  reactive power; units above 4.6 kVA) requires of generating units in German LV grids;
  a unit sized S̄ = P̄/0.90 meets it up to full output. Its active power may be slightly
  negative (SimBench's wind profiles: −1e-5 p.u., the turbine's own consumption at
  standstill), so |P| enters the power-factor limit.
- "Q at night" (night mode connected-q, beyond the paper): the solar units' S-limit
  √(S̄² − P²) alone, no power-factor limit.
- Reserve coefficient k ∈ [0, 1] (`check_reserve`): only (1 − k)·Qmax may be used for loss
  minimization; the paper sweeps `PAPER_KS`.

Reactive-power priority (an inverter's `priority=q`, IEEE 1547-2018 and OpenDSS's PVSystem
`WattPriority=no`): Q is given first and the active power yields. Every unit's capability
Qmax(P) rises from P = 0 to a peak (PV at P = 0.8·S̄, the inverter at 0.9·S̄, where the
power-factor line meets the S̄ circle) and falls beyond it (the S̄ circle; the DFIG curve
falls from P = 0, "Q at night" from P = 0): `q_peak` is the largest Qmax a unit whose
available power is P reaches by lowering it, `p_for_q` the largest active power at which
(1 − k)·Qmax still covers a setpoint Q — the power it keeps, the rest curtailed, so the
reserve k·Qmax stays free at the power it delivers. Only positive output is curtailed:
a unit drawing its own consumption (P < 0) keeps it.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from opfbench.errors import InputError

PF_MIN = 0.8
TAN_PHI_MAX = float(np.tan(np.arccos(PF_MIN)))  # 0.75
#: The generic inverter's power-factor range (VDE-AR-N 4105:2018-11, §5.7.2).
INVERTER_PF_MIN = 0.90
INVERTER_TAN_PHI_MAX = float(np.tan(np.arccos(INVERTER_PF_MIN)))  # 0.4843
P_TOLERANCE = 1e-9  # MW: P may exceed the rating by round-off only
KINDS = ("PV", "DFIG", "inverter")


def _check_p(p_mw: np.ndarray, rating_mw: np.ndarray, floor_mw: np.ndarray | None = None) -> None:
    """P finite, rating > 0, P ≤ rating and P ≥ 0 (or ≥ −floor_mw where a unit may consume)."""
    if not np.all(np.isfinite(p_mw)):
        raise InputError("DER active power contains NaN or inf")
    if np.any(rating_mw <= 0):
        raise InputError(f"DER rating must be positive, got {np.min(rating_mw)} MW")
    low = -P_TOLERANCE if floor_mw is None else -np.asarray(floor_mw) - P_TOLERANCE
    if np.any(p_mw < low):
        k = np.unravel_index(np.argmin(p_mw - low), np.shape(p_mw))
        bound = "0" if floor_mw is None else "−S̄"
        raise InputError(f"DER active power must be ≥ {bound}, got {np.asarray(p_mw)[k]:.6g} MW")
    over = p_mw - rating_mw
    if np.any(over > P_TOLERANCE):
        k = np.unravel_index(np.argmax(over), over.shape)
        raise InputError(
            f"DER active power {np.asarray(p_mw)[k]:.6g} MW exceeds its rating {np.broadcast_to(rating_mw, over.shape)[k]:.6g} MW"
        )


#: The reserve coefficients the paper sweeps, the default k list of every study.
PAPER_KS = (0.0, 0.2, 0.4, 0.6, 0.8)


def check_reserve(k: float) -> float:
    """One reserve coefficient k ∈ [0, 1], as a float; InputError otherwise (an array, NaN,
    or a number outside the range)."""
    if np.ndim(k) != 0:
        raise InputError(f"reserve coefficient k must be one number, got shape {np.shape(k)}")
    real = isinstance(k, (int, float, np.integer, np.floating)) or (isinstance(k, np.ndarray) and k.dtype.kind in "iuf")
    if isinstance(k, (bool, np.bool_)) or not real:
        raise InputError(f"reserve coefficient k must be a number in [0, 1], got {k!r}")
    value = float(k)
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise InputError(f"reserve coefficient k must lie in [0, 1], got {k}")
    return value


def pv_qmax(p_mw: np.ndarray, rating_mw: np.ndarray, s_mva: np.ndarray | None = None) -> np.ndarray:
    """PV inverter: min(P·tan(acos 0.8), √(S̄² − P²)) in MVAr (S̄ = `s_mva`, default P̄)."""
    p, r = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    s = r if s_mva is None else np.asarray(s_mva, float)
    _check_p(p, r)
    p = np.clip(p, 0.0, r)
    return np.minimum(p * TAN_PHI_MAX, np.sqrt(np.maximum(s**2 - p**2, 0.0)))


def pv_qmax_night(p_mw: np.ndarray, rating_mw: np.ndarray, s_mva: np.ndarray | None = None) -> np.ndarray:
    """'Q at night' variant beyond the paper: S-limited only, √(S̄² − P²), no PF limit."""
    p, r = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    s = r if s_mva is None else np.asarray(s_mva, float)
    _check_p(p, r)
    return np.sqrt(np.maximum(s**2 - np.clip(p, 0.0, r) ** 2, 0.0))


def dfig_qmax(p_mw: np.ndarray, rating_mw: np.ndarray) -> np.ndarray:
    """DFIG piecewise-linear capability curve in MVAr (per unit of P̄: 1 up to p = 0.4,
    then −5/6·p + 4/3 down to 0.5 at p = 1)."""
    p, s = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    _check_p(p, s)
    pu = np.clip(p / s, 0.0, 1.0)
    return s * np.where(pu <= 0.4, 1.0, -5.0 / 6.0 * pu + 4.0 / 3.0)


def inverter_qmax(p_mw: np.ndarray, rating_mw: np.ndarray, s_mva: np.ndarray, night: bool = False) -> np.ndarray:
    """Generic inverter: min(|P|·tan(acos 0.90), √(S̄² − P²)) in MVAr; `night` the S-limit
    alone ("Q at night"). P may be as low as −S̄ (a unit's own consumption)."""
    p, r, s = np.asarray(p_mw, float), np.asarray(rating_mw, float), np.asarray(s_mva, float)
    _check_p(p, r, floor_mw=s)
    s_limit = np.sqrt(np.maximum(s**2 - p**2, 0.0))
    return s_limit if night else np.minimum(np.abs(p) * INVERTER_TAN_PHI_MAX, s_limit)


def _columns(kinds: Sequence[str]) -> dict[str, np.ndarray]:
    """Each kind's DER columns; InputError for an unknown kind."""
    kinds_arr = np.asarray(kinds)
    unknown = set(kinds_arr.tolist()) - set(KINDS)
    if unknown:
        raise InputError(f"unknown DER kind(s) {sorted(unknown)}; expected one of {', '.join(KINDS)}")
    return {kind: kinds_arr == kind for kind in dict.fromkeys(kinds_arr.tolist())}


def qmax(
    kinds: Sequence[str],
    p_mw: np.ndarray,
    rating_mw: np.ndarray,
    s_mva: np.ndarray | None = None,
    night_q: bool | np.ndarray = False,
) -> np.ndarray:
    """Physical Qmax (MVAr) of each DER; `p_mw` shaped (n_der,) or (S, n_der), `s_mva` the
    nameplate S̄ per DER (default P̄). `night_q` (a bool, or a bool array broadcasting to
    `p_mw`) marks where a PV or inverter unit has the S-only "Q at night" limit; DFIG
    units keep their curve."""
    columns = _columns(kinds)
    p = np.asarray(p_mw, float)
    rating = np.broadcast_to(np.asarray(rating_mw, float), p.shape)
    s = rating if s_mva is None else np.broadcast_to(np.asarray(s_mva, float), p.shape)
    night = np.broadcast_to(np.asarray(night_q, dtype=bool), p.shape)
    out = np.zeros(p.shape)
    for kind, cols in columns.items():
        pc, rc, sc, nc = p[..., cols], rating[..., cols], s[..., cols], night[..., cols]
        if kind == "DFIG":
            out[..., cols] = dfig_qmax(pc, rc)
        elif kind == "PV":
            out[..., cols] = np.where(nc, pv_qmax_night(pc, rc, sc), pv_qmax(pc, rc, sc)) if nc.any() else pv_qmax(pc, rc, sc)
        else:
            day = inverter_qmax(pc, rc, sc)
            out[..., cols] = np.where(nc, inverter_qmax(pc, rc, sc, night=True), day) if nc.any() else day
    return out


def _peak_p(kinds: Sequence[str], s_mva: np.ndarray, night: np.ndarray) -> np.ndarray:
    """The active power (MW) at which each unit's Qmax peaks: where the power-factor line
    meets the S̄ circle (PV: cos φ 0.8, inverter: cos φ 0.90), 0 for a DFIG and for "Q at
    night" (no power-factor limit)."""
    out = np.zeros(np.shape(s_mva))
    for kind, cols in _columns(kinds).items():
        if kind != "DFIG":
            pf = PF_MIN if kind == "PV" else INVERTER_PF_MIN
            out[..., cols] = np.where(night[..., cols], 0.0, pf * s_mva[..., cols])
    return out


def q_peak(
    kinds: Sequence[str],
    p_mw: np.ndarray,
    rating_mw: np.ndarray,
    s_mva: np.ndarray | None = None,
    night_q: bool | np.ndarray = False,
) -> np.ndarray:
    """Reactive priority's capability (MVAr): the largest Qmax(P′) over the powers P′ a unit
    of available power P reaches by curtailing, P′ ∈ [min(P, 0), P] (module docstring);
    arguments as `qmax`."""
    p = np.asarray(p_mw, float)
    rating = np.broadcast_to(np.asarray(rating_mw, float), p.shape)
    s = rating if s_mva is None else np.broadcast_to(np.asarray(s_mva, float), p.shape)
    night = np.broadcast_to(np.asarray(night_q, dtype=bool), p.shape)
    at = np.clip(_peak_p(kinds, s, night), np.minimum(p, 0.0), p)
    return qmax(kinds, at, rating, s, night)


def p_for_q(
    kinds: Sequence[str],
    q_mvar: np.ndarray,
    p_mw: np.ndarray,
    rating_mw: np.ndarray,
    s_mva: np.ndarray | None = None,
    night_q: bool | np.ndarray = False,
    share: float = 1.0,
) -> np.ndarray:
    """Reactive priority's active power (MW): the largest P′ ≤ P (available, `p_mw`) at which
    share·Qmax(P′) ≥ |Q| (`share` = 1 − k), for setpoints Q within share·`q_peak`; P where
    P ≤ 0 or Q = 0. The S̄ circle gives P′ = √(S̄² − (Q/share)²), the DFIG curve
    P′/P̄ = 1.2·(4/3 − |Q|/(share·P̄)) where that is below 1 p.u. of P̄ (Qmax ≥ 0.5·P̄ everywhere)."""
    p, q = np.asarray(p_mw, float), np.abs(np.asarray(q_mvar, float))
    rating = np.broadcast_to(np.asarray(rating_mw, float), p.shape)
    s = rating if s_mva is None else np.broadcast_to(np.asarray(s_mva, float), p.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        needed = np.where(q > 0, q / share, 0.0)  # the Qmax the setpoint needs
    out = p.copy()
    for kind, cols in _columns(kinds).items():
        need, sc, rc = needed[..., cols], s[..., cols], rating[..., cols]
        if kind == "DFIG":
            keep = np.where(need > 0.5 * rc, 1.2 * (4.0 / 3.0 * rc - need), np.inf)
        else:
            keep = np.sqrt(np.maximum(sc**2 - need**2, 0.0))
        out[..., cols] = np.where(p[..., cols] > 0, np.minimum(p[..., cols], np.maximum(keep, 0.0)), p[..., cols])
    return out
