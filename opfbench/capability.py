"""DER reactive capability (paper §III). All quantities in MW/MVAr; Q positive =
injected (over-excited). Limits are symmetric: Qmin = −Qmax.

- PV: S̄ = P̄; |Q| ≤ P·tan(acos 0.8) = 0.75·P and |Q| ≤ √(S̄² − P²).
- DFIG: piecewise-linear in p = P/P̄: Qmax/P̄ = 1 for p ≤ 0.4; −5/6·p + 4/3 for 0.4 < p < 1;
  0.5 at p = 1.
- Reserve coefficient k ∈ [0, 1] (`check_reserve`): only (1 − k)·Qmax may be used for loss
  minimization; the paper sweeps `PAPER_KS`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from opfbench.errors import InputError

PF_MIN = 0.8
TAN_PHI_MAX = float(np.tan(np.arccos(PF_MIN)))  # 0.75
P_TOLERANCE = 1e-9  # MW: P may exceed the rating by round-off only


def _check_p(p_mw: np.ndarray, rating_mw: np.ndarray) -> None:
    if not np.all(np.isfinite(p_mw)):
        raise InputError("DER active power contains NaN or inf")
    if np.any(rating_mw <= 0):
        raise InputError(f"DER rating must be positive, got {np.min(rating_mw)} MW")
    if np.any(p_mw < -P_TOLERANCE):
        raise InputError(f"DER active power must be ≥ 0 MW, got {np.min(p_mw)} MW")
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
    value = float(k)
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise InputError(f"reserve coefficient k must lie in [0, 1], got {k}")
    return value


def pv_qmax(p_mw: np.ndarray, rating_mw: np.ndarray) -> np.ndarray:
    """PV inverter: min(P·tan(acos 0.8), √(S̄² − P²)) in MVAr (S̄ = P̄ = rating)."""
    p, s = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    _check_p(p, s)
    p = np.clip(p, 0.0, s)
    return np.minimum(p * TAN_PHI_MAX, np.sqrt(np.maximum(s**2 - p**2, 0.0)))


def pv_qmax_night(p_mw: np.ndarray, rating_mw: np.ndarray) -> np.ndarray:
    """'Q at night' variant beyond the paper: S-limited only, √(S̄² − P²), no PF limit."""
    p, s = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    _check_p(p, s)
    return np.sqrt(np.maximum(s**2 - np.clip(p, 0.0, s) ** 2, 0.0))


def dfig_qmax(p_mw: np.ndarray, rating_mw: np.ndarray) -> np.ndarray:
    """DFIG piecewise-linear capability curve in MVAr (per unit of P̄: 1 up to p = 0.4,
    then −5/6·p + 4/3 down to 0.5 at p = 1)."""
    p, s = np.asarray(p_mw, float), np.asarray(rating_mw, float)
    _check_p(p, s)
    pu = np.clip(p / s, 0.0, 1.0)
    return s * np.where(pu <= 0.4, 1.0, -5.0 / 6.0 * pu + 4.0 / 3.0)


def qmax(kinds: Sequence[str], p_mw: np.ndarray, rating_mw: np.ndarray, pv_night_q: bool = False) -> np.ndarray:
    """Physical Qmax (MVAr) of each DER; `p_mw` shaped (n_der,) or (S, n_der).

    `pv_night_q=True` applies the S-only limit to PV units (the "Q at night" variant).
    """
    kinds_arr = np.asarray(kinds)
    unknown = set(kinds_arr) - {"PV", "DFIG"}
    if unknown:
        raise InputError(f"unknown DER kind(s) {sorted(unknown)}; expected PV or DFIG")
    p = np.asarray(p_mw, float)
    rating = np.broadcast_to(np.asarray(rating_mw, float), p.shape)
    pv_limit = pv_qmax_night if pv_night_q else pv_qmax
    return np.where(kinds_arr == "PV", pv_limit(p, rating), dfig_qmax(p, rating))
