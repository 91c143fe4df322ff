"""Local rules learned from the certified optimum: how close can a communication-free rule
get? Each family is fitted per DER to the AC OPF's optimal Q over a training period, from
what that DER measures in closed loop — its own-bus |V| (p.u.), its own P (MW), its
own-bus load P (MW) and Q (MVAr); no time stamp, no other DER's data — and runs as a local
rule on the engine (`opfbench.strategies.rule_engine`): the target is clipped to ±(1 − k)·Qmax
like every rule's, and a rule of |V| is solved for its closed-loop steady state.

Families (Q positive = injected; q = Q/S̄ in p.u. of the DER's nameplate S̄):

- `learned-affine` (`AffineRule`): a linear decision rule
  q = a + b·P/S̄ + c·|V| + d·Q_load/S̄ per DER, with c ≤ 0 (Volt-VAR's sign, as the curves
  below: Q does not rise with the DER's own voltage).
- `learned-vv` (`VoltVarRule`): a monotone non-increasing piecewise-linear q(|V|) per DER,
  flat beyond its end knots — an optimized Volt-VAR curve. Its knots are fixed at
  quantiles of the DER's training voltages (`knots` of them, evenly spaced in
  probability), and only the values at the knots are fitted: with fixed knots the fit is
  a convex quadratic program (one global optimum, certified by Clarabel), whereas free
  breakpoints make it non-convex (local optima, starting-point dependent); quantile knots
  put the curve's resolution where the DER's voltages are.
- `learned-1547` (`Ieee1547Rule`): the IEEE 1547-2018 Volt-VAR shape — (V1, q1), (V2, 0),
  (V3, 0), (V4, q4), q1 ≥ 0 ≥ q4, flat beyond — with per-DER points. Non-convex in its
  breakpoints, so they are searched exhaustively on a grid of GRID_PU over the DER's
  training voltages (binned sums make each candidate O(1)), each candidate's q1 and q4 in
  closed form (a bounded one-variable least squares per side): the global optimum on the
  grid.

The fit is least squares on the training steps whose OPF point is a certified optimum
(status ok) and where the DER has a reactive limit (PV at night without "Q at night" has
none: any target gives Q = 0 there), features measured at the optimum (|V| from the power
flow at the optimal Q). Affine and Volt-VAR fits are one constrained least-squares
problem over all DERs in cvxpy (Clarabel), on the per-DER sufficient statistics (Gram
matrices), with a tiny ridge (RIDGE) that makes unidentifiable coefficients 0 (a bus with
no load gives no information on d). Every family obeys the **slope bound**
|∂Q_i/∂|V_i|| ≤ ρ / Σ_j |X_ij| with X the grid's voltage sensitivity at the DER buses
(`opfbench.strategies.sensitivity`, which derives it): the undamped closed-loop iteration
is then a contraction with factor ρ (option `rho`, default RHO) on the model it was fitted
on. The limits are not part of the fit: they are applied at evaluation, the same clip as
every rule's. Every family is also non-increasing in |V| (c ≤ 0): with X's entries positive
(injecting Q raises every voltage) the eigenvalues of diag(c)·X then lie in [−ρ, 0], and
the engine's damped iteration settles at a rate of about ½ per step; a rule whose Q rose
with its own voltage would be positive feedback, converging at rate ρ — 150 steps for
1e-7 at ρ = 0.9, beyond the engine's 100 (measured on 1-MV-rural: 69 of 102 unconstrained
affine fits had c > 0 and 32 of 1 344 test steps did not settle; with c ≤ 0, none).

End to end (`rounds=N`): N rounds of fit → closed-loop evaluation on the training period
→ refit with the voltages the rule itself produced in closed loop (the distribution it
meets at run time); the round with the fewest training steps outside the voltage band,
then the lowest closed-loop training losses, is kept (each round's figures are in the
parameters file).

Keeping the band (`comply=true`, the default): a slope-bounded rule cannot follow the
optimum's steep Q where the band binds, so a rule fitted to the optimum itself leaves the
band where the optimum just holds it (on 1-MV-rural for thousands of minutes). The fit is
therefore checked in closed loop on the training period and, while some step lies outside
the band, refitted to targets from the frontier below ε = 0: the optimum with the band
tightened by the next margin of MARGINS (`TrainingSet.tightened`, which the study layer
supplies). The first margin that leaves no training step outside is kept — else the one
with the fewest, then the lowest losses — and every margin tried is in the parameters
file (`fit["comply"]`).

A fitted rule is written as JSON (`LearnedParams.write`, format FORMAT): the family, the
case and its DERs (bus, S̄, P̄), the training period, the hash of the training data, the
sensitivity's row sums, the slope limits and the per-DER parameters. `params=FILE` makes
it a rule anywhere; the run's training (`train=START..END`) is fitted by `opfbench run`
(`opfbench.study.training_checks`), which ships the fitted parameters to its workers
(`install`).
"""

from __future__ import annotations

import hashlib
import json
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Protocol

import numpy as np

from opfbench.errors import InputError
from opfbench.jsonio import dumps, write_atomic
from opfbench.registry.options import Option, OptionValue
from opfbench.state import PROCESS
from opfbench.strategies.registration import local_rule

if TYPE_CHECKING:
    from opfbench.scenario import Scenario

FORMAT = "opfbench-learned-rule"
VERSION = 2  # 2: the network fitted on (network_sha256); slope limits = rho / row sums
RHO = 0.9  # the default contraction factor of the slope bound
KNOTS = 5  # learned-vv's default number of knots
GRID_PU = 0.0025  # learned-1547's breakpoint grid, p.u. of voltage
MAX_GRID = 161  # at most this many breakpoint candidates per DER (the grid widens beyond)
TOLERANCE = 1e-10  # Clarabel's gap and feasibility tolerances for the fits
RIDGE = 1e-9  # × the Gram matrix's mean diagonal: makes unidentifiable coefficients 0
MIN_LIMIT_SHARE = 1e-3  # a step is used for a DER where its limit exceeds this share of S̄
MARGINS = (0.0, 0.0025, 0.005, 0.01, 0.02, 0.03, 0.05)  # p.u.: the band's tightenings a compliant fit tries, in order
VIOLATION_PU = 1e-6  # a step lies outside the band beyond this
SAMPLES_PER_PARAMETER = 2  # a DER's fit needs twice as many samples as parameters (fewer: its ridge, not the data, decides)
#: The k and night mode the optimum is fitted at: the DER's whole capability (k = 0), PV
#: connected at night, no forecast; at evaluation the target is clipped to ±(1 − k)·Qmax.
TRAIN_K = 0.0
TRAIN_NIGHT = "connected"


class Measured(Protocol):
    """What a learned rule reads: the engine's `Measurements` or the training `Features`."""

    @property
    def v_pu(self) -> np.ndarray: ...
    @property
    def p_mw(self) -> np.ndarray: ...
    @property
    def load_p_mw(self) -> np.ndarray: ...
    @property
    def load_q_mvar(self) -> np.ndarray: ...
    @property
    def s_rated_mva(self) -> np.ndarray: ...


@dataclass(frozen=True)
class Features:
    """The measurements of the training steps, each (S, n_der): own-bus |V| p.u., own P MW,
    own-bus load P MW and Q MVAr; `s_rated_mva` (n_der,) the DERs' S̄."""

    v_pu: np.ndarray
    p_mw: np.ndarray
    load_p_mw: np.ndarray
    load_q_mvar: np.ndarray
    s_rated_mva: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (self.v_pu.shape[0], self.v_pu.shape[1])

    def with_v(self, v_pu: np.ndarray) -> "Features":
        return Features(v_pu, self.p_mw, self.load_p_mw, self.load_q_mvar, self.s_rated_mva)


# ----- the constrained least squares (cvxpy, Clarabel) -------------------------------------
def _block_lsq(gram: np.ndarray, rhs: np.ndarray, constraints: Callable[[Any], list]) -> np.ndarray:
    """argmin Σ_i θ_iᵀ G_i θ_i − 2 h_iᵀ θ_i over θ (n, K) under `constraints(θ)`: one
    problem over all DERs, as Σ_i ‖L_iᵀ θ_i − L_i⁻¹ h_i‖² with G_i + ridge = L_i L_iᵀ."""
    import cvxpy as cp
    import scipy.linalg as sla
    import scipy.sparse as sp

    n, k = rhs.shape
    if n == 0:
        return np.zeros((0, k))
    ridge = RIDGE * np.maximum(np.trace(gram, axis1=1, axis2=2) / k, 1.0)
    lower = np.linalg.cholesky(gram + ridge[:, None, None] * np.eye(k))
    target = np.stack([sla.solve_triangular(lower[i], rhs[i], lower=True) for i in range(n)])
    a = sp.block_diag([lower[i].T for i in range(n)], format="csr")
    theta = cp.Variable((n, k))
    flat = cp.reshape(theta, (n * k,), order="C")
    problem = cp.Problem(cp.Minimize(cp.sum_squares(a @ flat - target.reshape(-1))), constraints(theta))
    problem.solve(solver=cp.CLARABEL, tol_gap_abs=TOLERANCE, tol_gap_rel=TOLERANCE, tol_feas=TOLERANCE)
    if problem.status not in ("optimal", "optimal_inaccurate") or theta.value is None:
        raise InputError(f"the learned rule's least-squares fit failed (Clarabel: {problem.status})")
    return np.asarray(theta.value)


def _hat_basis(v: np.ndarray, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(left knot index j, weight w) of each v on the piecewise-linear basis of `knots`
    (flat beyond the ends): the curve through q at v is (1 − w)·q_j + w·q_{j+1}."""
    j = np.clip(np.searchsorted(knots, v, side="right") - 1, 0, len(knots) - 2)
    w = np.clip((v - knots[j]) / (knots[j + 1] - knots[j]), 0.0, 1.0)
    return j, w


# ----- the families -----------------------------------------------------------------------
class LearnedRule:
    """A family of local rules fitted per DER, scikit-learn style: hyper-parameters in the
    constructor, `fit` sets the per-DER parameters, `predict` gives Q targets (S, n_der)
    MVAr from measurements. `v_slope()` (n_der,) is each DER's largest |∂target/∂|V||,
    MVAr per p.u."""

    name: ClassVar[str]
    reads: ClassVar[tuple[str, ...]]
    hyper: ClassVar[tuple[str, ...]] = ()  # the constructor's hyper-parameters
    solver: ClassVar[str] = "clarabel (cvxpy)"

    @property
    def n_parameters(self) -> int:
        """Parameters fitted per DER."""
        raise NotImplementedError

    def __init__(self) -> None:
        self.s_rated_mva_ = np.zeros(0)  # (n_der,) S̄ of the DERs fitted, MVA

    def fit(self, x: Features, q_mvar: np.ndarray, slope_max: np.ndarray, use: np.ndarray) -> "LearnedRule":
        """Fit to the optimal `q_mvar` (S, n_der) on the steps `use` (S, n_der) bool, each
        DER's |∂Q/∂|V|| ≤ `slope_max` (n_der,) MVAr per p.u."""
        raise NotImplementedError

    def predict(self, m: Measured) -> np.ndarray:
        raise NotImplementedError

    def v_slope(self) -> np.ndarray:
        raise NotImplementedError

    def parameters(self) -> list[dict]:
        """Per DER, the fitted parameters as the params file holds them."""
        raise NotImplementedError

    @classmethod
    def from_parameters(cls, items: list, hyper: dict) -> "LearnedRule":
        """The rule of a params file's per-DER parameters; InputError (without context) if
        they are malformed."""
        raise NotImplementedError


class AffineRule(LearnedRule):
    """q = a + b·P/S̄ + c·|V| + d·Q_load/S̄ per DER, c ≤ 0; `coef_` (n_der, 4) [a, b, c, d]."""

    name = "learned-affine"
    reads = ("v", "p", "load")
    TERMS = ("a", "b", "c", "d")

    def __init__(self) -> None:
        super().__init__()
        self.coef_ = np.zeros((0, 4))

    @property
    def n_parameters(self) -> int:
        return len(self.TERMS)

    def fit(self, x: Features, q_mvar: np.ndarray, slope_max: np.ndarray, use: np.ndarray) -> "AffineRule":

        s = x.s_rated_mva
        # |V| centred on 1 p.u. for conditioning: θ = [a + c, b, c, d]
        z = np.stack([np.ones_like(x.v_pu), x.p_mw / s, x.v_pu - 1.0, x.load_q_mvar / s], axis=-1)  # (S, n, 4)
        z = np.where(use[..., None], z, 0.0)
        y = np.where(use, q_mvar / s, 0.0)
        gram = np.einsum("sik,sil->ikl", z, z)
        rhs = np.einsum("sik,si->ik", z, y)
        c_max = slope_max / s
        theta = _block_lsq(gram, rhs, lambda t: [t[:, 2] <= 0, t[:, 2] >= -c_max])
        theta[:, 2] = np.clip(theta[:, 2], -c_max, 0.0)  # the solver's tolerance, not a change of the fit
        self.coef_ = np.column_stack([theta[:, 0] - theta[:, 2], theta[:, 1], theta[:, 2], theta[:, 3]])
        self.s_rated_mva_ = np.asarray(s, dtype=float)
        return self

    def predict(self, m: Measured) -> np.ndarray:
        a, b, c, d = self.coef_.T
        s = m.s_rated_mva
        return a * s + b * m.p_mw + c * s * m.v_pu + d * m.load_q_mvar

    def v_slope(self) -> np.ndarray:
        return np.abs(self.coef_[:, 2]) * self.s_rated_mva_

    def parameters(self) -> list[dict]:
        return [dict(zip(self.TERMS, map(float, row), strict=True)) for row in self.coef_]

    @classmethod
    def from_parameters(cls, items: list, hyper: dict) -> "AffineRule":
        rule = cls()
        try:
            rule.coef_ = np.array([[float(item[t]) for t in cls.TERMS] for item in items]).reshape(-1, 4)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"each DER's parameters must be numbers {', '.join(cls.TERMS)}") from None
        if not np.isfinite(rule.coef_).all():
            raise InputError("a parameter is not finite")
        rising = np.flatnonzero(rule.coef_[:, 2] > 0)
        if rising.size:
            i = int(rising[0])
            raise InputError(
                f"DER {i + 1}'s c = {rule.coef_[i, 2]:.6g} > 0: its Q would rise with its own |V| (positive feedback); "
                "the fit keeps c ≤ 0"
            )
        return rule


class _CurveRule(LearnedRule):
    """A piecewise-linear q(|V|) per DER through the points (`v_`, `q_`) (n_der, K), flat
    beyond its ends, q non-increasing in |V|."""

    reads = ("v",)

    def __init__(self) -> None:
        super().__init__()
        self.v_ = np.zeros((0, 2))
        self.q_ = np.zeros((0, 2))

    def predict(self, m: Measured) -> np.ndarray:
        v = m.v_pu
        out = np.empty(v.shape)
        for i in range(v.shape[1]):
            out[:, i] = np.interp(v[:, i], self.v_[i], self.q_[i])
        return out * m.s_rated_mva

    def v_slope(self) -> np.ndarray:
        dv = np.diff(self.v_, axis=1)
        dq = -np.diff(self.q_, axis=1)
        slope = np.where(dv > 0, dq / np.where(dv > 0, dv, 1.0), 0.0)
        return slope.max(axis=1, initial=0.0) * self.s_rated_mva_

    def parameters(self) -> list[dict]:
        return [{"v": [float(x) for x in v], "q": [float(x) for x in q]} for v, q in zip(self.v_, self.q_, strict=True)]

    @classmethod
    def from_parameters(cls, items: list, hyper: dict) -> "_CurveRule":
        rule = cls()
        try:
            v = np.array([[float(x) for x in item["v"]] for item in items])
            q = np.array([[float(x) for x in item["q"]] for item in items])
        except (KeyError, TypeError, ValueError):
            raise InputError("each DER's parameters must be the curve's points v and q (lists of numbers)") from None
        if v.ndim != 2 or v.shape != q.shape or v.shape[1] < 2:
            raise InputError("each DER's curve needs as many v as q values, at least 2, the same for every DER")
        if not (np.isfinite(v).all() and np.isfinite(q).all()):
            raise InputError("a curve point is not finite")
        if (np.diff(v, axis=1) < 0).any() or (np.diff(q, axis=1) > 0).any():
            raise InputError("a curve's voltages must not decrease and its q values must not increase")
        if ((np.diff(v, axis=1) == 0) & (np.diff(q, axis=1) != 0)).any():
            raise InputError("a curve has a vertical step (two q values at one voltage)")
        if (np.abs(q) > 1).any():
            raise InputError("a curve's q values are per unit of S̄ and must lie in [−1, 1]")
        rule.v_, rule.q_ = v, q
        return rule


class VoltVarRule(_CurveRule):
    """Monotone non-increasing piecewise-linear q(|V|) with `knots` knots at quantiles of
    each DER's training voltages (module docstring)."""

    name = "learned-vv"
    hyper = ("knots",)

    def __init__(self, knots: int = KNOTS) -> None:
        super().__init__()
        self.knots = knots

    @property
    def n_parameters(self) -> int:
        return self.knots

    def fit(self, x: Features, q_mvar: np.ndarray, slope_max: np.ndarray, use: np.ndarray) -> "VoltVarRule":
        import cvxpy as cp

        s = x.s_rated_mva
        n, k = len(s), self.knots
        knots = np.zeros((n, k))
        gram, rhs = np.zeros((n, k, k)), np.zeros((n, k))
        for i in range(n):
            v, y = x.v_pu[use[:, i], i], q_mvar[use[:, i], i] / s[i]
            knots[i] = _quantile_knots(v, k)
            j, w = _hat_basis(v, knots[i])
            for a, wa in ((j, 1 - w), (j + 1, w)):
                np.add.at(rhs[i], a, wa * y)
                for b, wb in ((j, 1 - w), (j + 1, w)):
                    np.add.at(gram[i], (a, b), wa * wb)
        step = np.diff(knots, axis=1)
        drop = (slope_max / s)[:, None] * step

        def constraints(t):
            fall = t[:, :-1] - t[:, 1:]
            return [fall >= 0, fall <= drop, cp.abs(t) <= 1]

        q = _block_lsq(gram, rhs, constraints)
        self.v_, self.q_ = knots, _monotone(q, drop)
        self.s_rated_mva_ = np.asarray(s, dtype=float)
        return self

    @classmethod
    def from_parameters(cls, items: list, hyper: dict) -> "VoltVarRule":
        rule = super().from_parameters(items, hyper)
        assert isinstance(rule, VoltVarRule)
        rule.knots = rule.v_.shape[1]
        return rule


def _quantile_knots(v: np.ndarray, k: int) -> np.ndarray:
    """`k` strictly increasing knots at the quantiles of `v` (at least 1e-4 p.u. apart;
    around 1 p.u. where there are no data)."""
    base = np.quantile(v, np.linspace(0, 1, k)) if v.size else np.full(k, 1.0)
    out = base.copy()
    for i in range(1, k):
        out[i] = max(out[i], out[i - 1] + 1e-4)
    return out


def _monotone(q: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """The solver's point with its last tolerance removed: each step down within [0,
    drop], |q| ≤ 1 (changes of the order of the solver's tolerance, 1e-8)."""
    out = np.clip(q, -1.0, 1.0)
    for i in range(1, out.shape[1]):
        out[:, i] = np.clip(out[:, i], out[:, i - 1] - drop[:, i - 1], out[:, i - 1])
    return out


class Ieee1547Rule(_CurveRule):
    """The IEEE 1547 Volt-VAR shape per DER, points (V1, q1), (V2, 0), (V3, 0), (V4, q4)
    searched on a GRID_PU grid (module docstring)."""

    name = "learned-1547"
    solver = f"grid search ({GRID_PU} p.u.)"

    @property
    def n_parameters(self) -> int:
        return 4  # V1, V4 and q1, q4 (V2, V3 where q is 0)

    def fit(self, x: Features, q_mvar: np.ndarray, slope_max: np.ndarray, use: np.ndarray) -> "Ieee1547Rule":
        s = x.s_rated_mva
        n = len(s)
        self.v_, self.q_ = np.zeros((n, 4)), np.zeros((n, 4))
        for i in range(n):
            self.v_[i], self.q_[i] = _fit_1547(x.v_pu[use[:, i], i], q_mvar[use[:, i], i] / s[i], slope_max[i] / s[i])
        self.s_rated_mva_ = np.asarray(s, dtype=float)
        return self


def _grid(v: np.ndarray) -> np.ndarray:
    """Breakpoint candidates: a GRID_PU grid over the voltages (one step beyond each end),
    at most MAX_GRID points."""
    lo, hi = (float(v.min()), float(v.max())) if v.size else (1.0, 1.0)
    step = max(GRID_PU, (hi - lo + 2 * GRID_PU) / (MAX_GRID - 1))
    start = np.floor(lo / step) * step - step
    return start + step * np.arange(int(np.ceil((hi - start) / step)) + 2)


def _fit_1547(v: np.ndarray, y: np.ndarray, slope_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(v points (4,), q points (4,)) of the best 1547 shape for samples (v, y = Q/S̄): the
    exhaustive search over breakpoints on `_grid(v)`; each side's amplitude is the bounded
    least squares q = clip(Σyφ / Σφ², cap) with cap = min(1, slope_max·(V2 − V1))."""
    g = _grid(v)
    order = np.argsort(v)
    vs, ys = v[order], y[order]
    pos = np.searchsorted(vs, g, side="left")  # samples below each grid point

    def prefix(values: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(values)])[pos]

    cnt, sy, sv, svy, svv = prefix(np.ones_like(vs)), prefix(ys), prefix(vs), prefix(vs * ys), prefix(vs * vs)
    lo, hi = np.triu_indices(len(g), k=1)  # candidate pairs (lower breakpoint, upper breakpoint)
    width = g[hi] - g[lo]
    cap = np.minimum(1.0, slope_max * width)
    n_in, y_in, v_in, vy_in, vv_in = (arr[hi] - arr[lo] for arr in (cnt, sy, sv, svy, svv))

    def side(a: np.ndarray, b: np.ndarray, sign: float) -> tuple[np.ndarray, np.ndarray]:
        amplitude = np.clip(np.divide(a, b, out=np.zeros_like(a), where=b > 0) * sign, 0.0, cap) * sign
        return 2 * amplitude * a - amplitude**2 * b, amplitude

    # low side: φ = 1 below V1 = g[lo], (V2 − v)/w between, 0 from V2 = g[hi] on
    a_low = sy[lo] + (g[hi] * y_in - vy_in) / width
    b_low = cnt[lo] + (g[hi] ** 2 * n_in - 2 * g[hi] * v_in + vv_in) / width**2
    gain_low, q_low = side(a_low, b_low, 1.0)
    # high side: φ = 0 below V3 = g[lo], (v − V3)/w between, 1 from V4 = g[hi] on
    a_high = (sy[-1] - sy[hi]) + (vy_in - g[lo] * y_in) / width
    b_high = (cnt[-1] - cnt[hi]) + (vv_in - 2 * g[lo] * v_in + g[lo] ** 2 * n_in) / width**2
    gain_high, q_high = side(a_high, b_high, -1.0)
    best_low = np.full(len(g), -np.inf)  # by V2's grid index
    np.maximum.at(best_low, hi, gain_low)
    best_high = np.full(len(g), -np.inf)  # by V3's grid index
    np.maximum.at(best_high, lo, gain_high)
    suffix = np.maximum.accumulate(best_high[::-1])[::-1]  # best high side with V3 ≥ each index
    b2 = int(np.argmax(best_low + suffix))
    b3 = b2 + int(np.argmax(best_high[b2:]))
    low = np.flatnonzero((hi == b2) & (gain_low == best_low[b2]))[0]
    high = np.flatnonzero((lo == b3) & (gain_high == best_high[b3]))[0]
    points = np.array([g[lo[low]], g[b2], g[b3], g[hi[high]]])
    return points, np.array([q_low[low], 0.0, 0.0, q_high[high]])


FAMILIES: dict[str, type[LearnedRule]] = {f.name: f for f in (AffineRule, VoltVarRule, Ieee1547Rule)}


def family_rule(family: str, options: dict) -> LearnedRule:
    """An unfitted rule of `family` with the hyper-parameters among `options`."""
    cls = FAMILIES[family]
    return cls(**{key: options[key] for key in cls.hyper if key in options})


# ----- training -----------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainingSet:
    """The training period's operating points and the optimum on them: `scenario` (k = 0,
    PV connected at night, no forecast), the AC OPF's optimal Q `q_mvar` (S, n_der) MVAr and
    `ok` (S,) the steps whose point is a certified optimum (status ok); `case` the case
    spec trained on, `period` the training period as given (START..END, END excluded),
    `start`/`end` its first and last step (ISO); `tightened(margin)` (None: not given) the
    optimum with every bus's voltage band tightened by `margin` p.u., as (q_mvar, ok) — the
    targets of a compliant fit (module docstring)."""

    case: str
    period: str
    start: str
    end: str
    scenario: Scenario
    q_mvar: np.ndarray
    ok: np.ndarray
    tightened: Callable[[float], tuple[np.ndarray, np.ndarray]] | None = field(default=None, compare=False)

    def digest(self) -> str:
        """sha256 of the training data: every load's and DER's values, the optimum, the steps used."""
        sc = self.scenario
        h = hashlib.sha256()
        for arr in (sc.load_scale, sc.load_p_mw, sc.load_q_mvar, sc.der_p_mw, self.q_mvar, self.ok):
            h.update(b"-" if arr is None else np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()


def features(scenario: Scenario, v_pu: np.ndarray) -> Features:
    """The training features: `v_pu` (S, n_der) at the DER buses, the rest from `scenario`."""
    net = scenario.net
    return Features(v_pu, scenario.der_p_mw, scenario.load_p_at_der_mw(), scenario.load_q_at_der_mvar(), net.der_s_mva)


@dataclass(frozen=True)
class ClosedLoop:
    """A rule's closed loop on the training period at TRAIN_K: |V| at the DER buses
    (S, n_der), mean losses (kW), steps not settled, steps outside the voltage band and the
    worst excursion beyond it (p.u.)."""

    v_der: np.ndarray
    loss_kw: float
    not_settled: int
    outside: int
    max_violation_pu: float

    def record(self) -> dict:
        return {
            "train_loss_kw": self.loss_kw,
            "not_settled_steps": self.not_settled,
            "outside_steps": self.outside,
            "max_violation_pu": self.max_violation_pu,
        }


def _closed_loop(rule: LearnedRule, scenario: Scenario) -> ClosedLoop:
    """`rule` in closed loop on `scenario` at TRAIN_K (`ClosedLoop`)."""
    from opfbench.strategies.rule_engine import run_rule
    from opfbench.strategies.rules import Rule

    res = run_rule(rule.name, Rule(rule.name, lambda m: rule.predict(m), frozenset(rule.reads)), scenario, TRAIN_K, {})
    violation = res.voltage_violation()
    return ClosedLoop(
        res.vm[:, scenario.net.der_bus],
        float(np.nanmean(res.losses_kw)),
        int((res.status == "not-settled").sum()),
        int((violation > VIOLATION_PU).sum()),
        float(np.nanmax(violation, initial=0.0)),
    )


def usable(scenario: Scenario) -> np.ndarray:
    """(S, n_der) the steps where each DER has a reactive limit (above MIN_LIMIT_SHARE of
    S̄): where a target can act, so where a fit can learn from the optimum."""
    return scenario.qmax_mvar() > MIN_LIMIT_SHARE * scenario.net.der_s_mva


def check_samples(rule: LearnedRule, net, samples: np.ndarray, where: str) -> None:
    """InputError naming the DER (name, bus) that has fewer than SAMPLES_PER_PARAMETER ×
    the family's parameters of training samples (`samples` (n_der,)): a rule is never
    fitted to no data."""
    need = SAMPLES_PER_PARAMETER * rule.n_parameters
    short = np.flatnonzero(np.asarray(samples) < need)
    if short.size:
        i = int(short[0])
        more = f" (and {short.size - 1} more DER)" if short.size > 1 else ""
        raise InputError(
            f"{rule.name}: DER {net.der_names[i]} (bus {int(net.bus_ids[net.der_bus[i]])}) has {int(samples[i])} training "
            f"samples in {where}; its {rule.n_parameters} parameters need at least {need}{more} — train over a longer "
            "period, or one with DER output (not only night)"
        )


def network_digest(net) -> str:
    """sha256 of a network's model — buses, branches, loads, generators, DER — without its
    name: the identity of the grid a rule was fitted on."""
    from dataclasses import fields

    from opfbench.digests import digest

    return digest({f.name: getattr(net, f.name) for f in fields(net) if f.name != "name"})


def grid_contraction(net, slope_mvar_per_pu: np.ndarray) -> float:
    """The closed loop's contraction factor max_i |c_i|·Σ_j |X_ij| (`sensitivity`) on `net`
    with X measured at its nominal loads, DER at 0 and at 0.8 of rating (the larger)."""
    from opfbench.scenario import Scenario
    from opfbench.strategies.sensitivity import contraction_factor, voltage_sensitivity

    return max(
        contraction_factor(voltage_sensitivity(Scenario.snapshot(net, der_scale=d)), slope_mvar_per_pu) for d in (0.0, 0.8)
    )


def _rank(loop: ClosedLoop) -> tuple[int, float]:
    """Fewer training steps outside the band first, then lower losses."""
    return loop.outside, loop.loss_kw


def _fit_at(
    new: Callable[[], LearnedRule], training: TrainingSet, q_mvar: np.ndarray, ok: np.ndarray, slope_max: np.ndarray, rounds: int
) -> tuple[LearnedRule, Features, np.ndarray, list[dict], ClosedLoop | None]:
    """The rule fitted to the targets `q_mvar` (certified at `ok`) with `rounds` end-to-end
    refits: (rule, features at the targets, steps used, each round's record, the kept
    rule's closed loop where one was run)."""
    from opfbench.powerflow import solve_pf_batch

    sc = training.scenario
    net = sc.net
    pf = solve_pf_batch(net, sc.injections(q_mvar))
    converged = np.asarray(pf.converged, dtype=bool)
    x = features(sc, np.abs(pf.v[:, net.der_bus]))
    use = (ok & converged)[:, None] & usable(sc)
    where = f"{training.case} over {training.period}"
    check_samples(new(), net, use.sum(axis=0), f"{where} (steps whose optimum is certified and where it has a reactive limit)")
    rule = new().fit(x, q_mvar, slope_max, use)
    history: list[dict] = []
    if not rounds:
        return rule, x, use, history, None
    best = rule
    loop = best_loop = _closed_loop(rule, sc)
    history.append({"round": 0} | loop.record())
    for r in range(1, rounds + 1):
        closed = use & np.isfinite(loop.v_der)
        check_samples(new(), net, closed.sum(axis=0), f"{where}, round {r} (steps the rule settled in closed loop)")
        rule = new().fit(x.with_v(loop.v_der), q_mvar, slope_max, closed)
        loop = _closed_loop(rule, sc)
        history.append({"round": r} | loop.record())
        if _rank(loop) < _rank(best_loop):
            best, best_loop = rule, loop
    return best, x, use, history, best_loop


def fit_rule(
    family: str, training: TrainingSet, rho: float = RHO, rounds: int = 0, knots: int = KNOTS, comply: bool = True
) -> "LearnedParams":
    """Fit `family` to `training` (module docstring); `rounds` end-to-end refits; `comply`
    refits to the optimum of tightened bands until the rule holds the band in closed loop
    on the training period (where `training.tightened` is given)."""
    from opfbench.strategies.sensitivity import contraction_factor, slope_limit, voltage_sensitivity

    sc = training.scenario
    net = sc.net
    x_sens = voltage_sensitivity(sc.take(np.flatnonzero(training.ok)) if training.ok.any() else sc)
    slope_max = slope_limit(x_sens, rho)
    hyper = {key: value for key, value in {"knots": knots}.items() if key in FAMILIES[family].hyper}

    def new() -> LearnedRule:
        return family_rule(family, hyper)

    q_mvar, ok = training.q_mvar, training.ok
    rule, x, use, history, loop = _fit_at(new, training, q_mvar, ok, slope_max, rounds)
    margins: list[dict] = []
    if comply and training.tightened is not None:
        loop = loop if loop is not None else _closed_loop(rule, sc)
        margins.append({"margin_pu": 0.0} | loop.record())
        chosen = (rule, x, use, history, loop, q_mvar, 0.0)
        width = float(np.delete(net.vmax - net.vmin, net.slack).min(initial=np.inf))
        for margin in (m for m in MARGINS[1:] if m < width / 2):  # a margin must leave a band
            if chosen[4].outside == 0:
                break
            q_t, ok_t = training.tightened(margin)
            fit = _fit_at(new, training, q_t, ok_t, slope_max, rounds)
            tried = fit[4] if fit[4] is not None else _closed_loop(fit[0], sc)
            margins.append({"margin_pu": margin} | tried.record())
            if _rank(tried) < _rank(chosen[4]):
                chosen = (fit[0], fit[1], fit[2], fit[3], tried, q_t, margin)
        rule, x, use, history, loop, q_mvar, _ = chosen
    fitted = rule.predict(x)
    err = np.where(use, fitted - q_mvar, np.nan) / net.der_s_mva
    return LearnedParams(
        family=family,
        case=training.case,
        network=net.name,
        der_bus=tuple(int(b) for b in net.bus_ids[net.der_bus]),
        s_rated_mva=tuple(float(v) for v in net.der_s_mva),
        network_sha256=network_digest(net),
        train={
            "period": training.period,
            "start": training.start,
            "end": training.end,
            "steps": int(sc.n_snapshots),
            "optimal_steps": int(training.ok.sum()),
            "samples_used": int(use.sum()),
        },
        data_sha256=training.digest(),
        rho=float(rho),
        hyper=hyper | {"rounds": rounds, "comply": comply},
        row_sum_pu_per_mvar=tuple(float(v) for v in np.abs(x_sens).sum(axis=1)),
        slope_max_mvar_per_pu=tuple(float(v) for v in slope_max),
        rule=rule,
        fit={
            "solver": rule.solver,
            "rmse_pu": [float(v) if np.isfinite(v) else None for v in np.sqrt(np.nanmean(err**2, axis=0))] if use.any() else [],
            "contraction_factor": contraction_factor(x_sens, rule.v_slope()),
            "rounds": history,
            "comply": margins,
        },
    )


# ----- the parameters file ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LearnedParams:
    """A fitted rule and where it comes from (the params file's content, module docstring).
    `der_bus` external bus numbers and `s_rated_mva` S̄ of the DERs in the network's order;
    `row_sum_pu_per_mvar` Σ_j |X_ij| and `slope_max_mvar_per_pu` ρ / Σ_j |X_ij| per DER."""

    family: str
    case: str
    network: str
    der_bus: tuple[int, ...]
    s_rated_mva: tuple[float, ...]
    network_sha256: str
    train: dict
    data_sha256: str
    rho: float
    hyper: dict
    row_sum_pu_per_mvar: tuple[float, ...]
    slope_max_mvar_per_pu: tuple[float, ...]
    rule: LearnedRule
    fit: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "family": self.family,
            "case": self.case,
            "network": self.network,
            "ders": [{"bus": b, "s_mva": s} for b, s in zip(self.der_bus, self.s_rated_mva, strict=True)],
            "network_sha256": self.network_sha256,
            "train": self.train,
            "data_sha256": self.data_sha256,
            "rho": self.rho,
            "hyper": self.hyper,
            "row_sum_pu_per_mvar": list(self.row_sum_pu_per_mvar),
            "slope_max_mvar_per_pu": list(self.slope_max_mvar_per_pu),
            "parameters": self.rule.parameters(),
            "fit": self.fit,
        }

    def text(self) -> str:
        return dumps(self.as_dict()) + "\n"

    def write(self, path: str | Path) -> Path:
        return write_atomic(path, self.text())

    @property
    def digest(self) -> str:
        """sha256 of the file's text: the fitted rule's identity."""
        return hashlib.sha256(self.text().encode()).hexdigest()

    @classmethod
    def parse(cls, text: str, ref: str) -> "LearnedParams":
        """The params file `ref`'s `text`, checked; InputError naming `ref` otherwise."""
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise InputError(f"learned-rule parameters {ref}: not JSON ({exc})") from None
        try:
            return cls._from_dict(data)
        except InputError as exc:
            raise InputError(f"learned-rule parameters {ref}: {exc}") from None

    @classmethod
    def _from_dict(cls, data: object) -> "LearnedParams":
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f'not a learned rule\'s parameters (no "format": "{FORMAT}")')
        if data.get("version") != VERSION:
            raise InputError(f"format version {data.get('version')!r}; this opfbench reads version {VERSION}")
        family = data.get("family")
        if family not in FAMILIES:
            raise InputError(f"unknown family {family!r}; one of {', '.join(FAMILIES)}")
        ders, items = data.get("ders"), data.get("parameters")
        if not isinstance(ders, list) or not isinstance(items, list) or len(ders) != len(items):
            raise InputError('"ders" and "parameters" must be lists with one entry per DER')
        try:
            bus = tuple(int(d["bus"]) for d in ders)
            s = tuple(float(d["s_mva"]) for d in ders)
            row_sum = tuple(float(v) for v in data["row_sum_pu_per_mvar"])
            slope_max = tuple(float(v) for v in data["slope_max_mvar_per_pu"])
            rho = float(data["rho"])
            case, network, digest = str(data["case"]), str(data["network"]), str(data["data_sha256"])
            network_sha = str(data["network_sha256"])
            train, hyper = dict(data["train"]), dict(data.get("hyper") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"a field is missing or malformed ({type(exc).__name__}: {exc})") from None
        if not (len(row_sum) == len(slope_max) == len(bus)):
            raise InputError("the sensitivity and slope lists need one value per DER")
        if not all(np.isfinite(v) and v > 0 for v in (*s, *row_sum)) or not 0 < rho < 1:
            raise InputError("S̄ and the sensitivity's row sums must be positive and finite, rho in (0, 1)")
        bound = rho / np.array(row_sum)  # the slope bound the fit guarantees: ρ / Σ_j |X_ij|
        if not np.allclose(slope_max, bound, rtol=1e-9, atol=0.0):
            i = int(np.flatnonzero(~np.isclose(slope_max, bound, rtol=1e-9, atol=0.0))[0])
            raise InputError(
                f"DER at bus {bus[i]}: slope limit {slope_max[i]:.6g} MVAr/p.u. is not rho / row sum = "
                f"{rho:g} / {row_sum[i]:.6g} = {bound[i]:.6g}"
            )
        rule = FAMILIES[family].from_parameters(items, hyper)
        rule.s_rated_mva_ = np.array(s)
        over = rule.v_slope() > bound * (1 + 1e-6)
        if over.any():
            i = int(np.flatnonzero(over)[0])
            raise InputError(
                f"DER at bus {bus[i]}: |∂Q/∂|V|| = {rule.v_slope()[i]:.6g} MVAr/p.u. exceeds its slope bound "
                f"rho / Σ|X| = {bound[i]:.6g}: the closed loop would not be a contraction"
            )
        fit = dict(data.get("fit") or {})
        return cls(family, case, network, bus, s, network_sha, train, digest, rho, hyper, row_sum, slope_max, rule, fit)

    def check_network(self, net, ref: str) -> None:
        """InputError unless `net` is the grid this rule was fitted on — its DERs (bus numbers
        and S̄, in order) and its whole model (`network_digest`) — and its slopes make the
        closed loop a contraction there (`grid_contraction` < 1: a file's row sums are its
        own word; the grid's sensitivity is measured anew)."""
        buses = tuple(int(b) for b in net.bus_ids[net.der_bus])
        if len(buses) != len(self.der_bus):
            raise InputError(
                f"learned-rule parameters {ref} were fitted on {self.case} ({self.network}, {len(self.der_bus)} DER); "
                f"{net.name} has {len(buses)} DER"
            )
        if buses != self.der_bus or not np.allclose(net.der_s_mva, self.s_rated_mva, rtol=1e-9, atol=0.0):
            raise InputError(
                f"learned-rule parameters {ref} were fitted on {self.case} ({self.network}): its DERs (buses, S̄) are not "
                f"those of {net.name}"
            )
        if network_digest(net) != self.network_sha256:
            raise InputError(
                f"learned-rule parameters {ref} were fitted on {self.case} ({self.network}); {net.name} is another "
                "grid (its branches, loads, limits or DER differ, network sha256 "
                f"{network_digest(net)[:12]}… ≠ {self.network_sha256[:12]}…): fit the rule on this case"
            )
        factor = grid_contraction(net, self.rule.v_slope())
        if factor >= 1:
            raise InputError(
                f"learned-rule parameters {ref}: on {net.name} its slopes make the closed loop no contraction (factor "
                f"{factor:.3g} ≥ 1 with the grid's own sensitivity at its nominal loads; the fit keeps it at rho = "
                f"{self.rho:g} on its training states): its sensitivities (row sums) are not this grid's"
            )

    def check_measurements(self, m: Measured, ref: str) -> None:
        """InputError unless the measured DERs are this rule's (count and S̄)."""
        s = np.asarray(m.s_rated_mva, dtype=float)
        if s.shape != (len(self.s_rated_mva),) or not np.allclose(s, self.s_rated_mva, rtol=1e-9, atol=0.0):
            raise InputError(
                f"learned-rule parameters {ref} were fitted on {self.case} ({len(self.s_rated_mva)} DER); "
                f"the network measured has {s.size} DER of other ratings"
            )


# ----- parameters at run time ---------------------------------------------------------------
_installed: dict[str, LearnedParams] = PROCESS.table("installed learned rules")
_files: dict[tuple, LearnedParams] = PROCESS.table("learned-rule files read")
_lock = threading.Lock()


def forget() -> None:
    """Forget every installed fitted rule and every file read."""
    with _lock:
        _installed.clear()
        _files.clear()


PROCESS.on_reset("learned rules", forget)


def install(params: dict[str, LearnedParams]) -> None:
    """Make fitted rules known under their references (a worker process receives a run's
    fitted rules this way: no access to the run folder needed)."""
    with _lock:
        _installed.update(params)


def load_params(ref: str) -> LearnedParams:
    """The fitted rule `ref`: one installed under that reference, else the file (cached by
    path, modification time and size); InputError naming it if missing or malformed."""
    with _lock:
        if ref in _installed:
            return _installed[ref]
    path = Path(ref)
    try:
        st = path.stat()
    except OSError:
        raise InputError(f"learned-rule parameters {ref}: no such file") from None
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    with _lock:
        if key in _files:
            return _files[key]
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"learned-rule parameters {ref}: cannot read it ({exc})") from None
    params = LearnedParams.parse(text, ref)
    with _lock:
        _files[key] = params
    return params


def fitted(family: str, params: str, train: str) -> LearnedParams:
    """The fitted rule a label's options name: `params` (a file or an installed reference)
    of the family `family`; InputError where there is none."""
    if not params:
        raise InputError(
            f"{family}:train={train} is fitted by opfbench run (the AC OPF over the training period, then the fit); "
            f"elsewhere give params=FILE (a run folder's learned/*.json)"
        )
    got = load_params(params)
    if got.family != family:
        raise InputError(f"learned-rule parameters {params} are of {got.family}, not {family}")
    return got


def check_options(family: str, options: dict) -> None:
    """A learned configuration: train= or params= (one of them); a training period
    written START..END; fit options only with train=; a params file that loads."""
    train, params = options["train"], options["params"]
    if bool(train) == bool(params):
        raise InputError(
            f"{family}: give train=START..END (fitted by opfbench run to the AC OPF over that period) or params=FILE "
            "(a fitted rule), one of them"
        )
    if train:
        start, sep, end = train.partition("..")
        if not (sep and start.strip() and end.strip()):
            raise InputError(f"{family}: train must be a period START..END (END excluded), e.g. 2016-01-01..2016-10-01")
    else:
        fit_options = {"rho": RHO, "rounds": 0, "knots": KNOTS, "comply": True}
        given = [key for key, default in fit_options.items() if key in options and options[key] != default]
        if given:
            raise InputError(f"{family}: {', '.join(given)} are options of the fit; with params= the rule is fitted already")
        fitted(family, params, train)


def check_affine(options: dict) -> None:
    check_options(AffineRule.name, options)


def check_vv(options: dict) -> None:
    if not 2 <= options["knots"] <= 50:
        raise InputError(f"learned-vv: knots must lie in 2..50, got {options['knots']}")
    check_options(VoltVarRule.name, options)


def check_ieee1547(options: dict) -> None:
    check_options(Ieee1547Rule.name, options)


def _target(family: str, m: Measured, train: str, params: str) -> np.ndarray:
    got = fitted(family, params, train)
    got.check_measurements(m, params)
    return got.rule.predict(m)


def fit_configuration(family: str, training: TrainingSet, options: dict) -> LearnedParams:
    """The registry's `fit` of the learned strategies: `fit_rule` with the label's fit options."""
    return fit_rule(
        family,
        training,
        rho=options["rho"],
        rounds=options["rounds"],
        knots=options.get("knots", KNOTS),
        comply=options["comply"],
    )


def _rho(value: OptionValue) -> str | None:
    return None if isinstance(value, float) and 0 < value < 1 else f"a contraction factor lies in (0, 1), got {value}"


def _rounds(value: OptionValue) -> str | None:
    return None if isinstance(value, int) and 0 <= value <= 20 else f"rounds lie in 0..20, got {value}"


#: A learned strategy's options: where its parameters come from, and the fit's.
TRAIN = Option("train", "", "training period START..END (END excluded): opfbench run fits the rule to the AC OPF over it")
PARAMS = Option("params", "", "a fitted rule's parameters (JSON: a run folder's learned/*.json)")
LEARNED_OPTIONS = (
    TRAIN,
    PARAMS,
    Option("rho", RHO, "the slope bound's contraction factor ρ: |∂Q_i/∂|V_i|| ≤ ρ / Σ_j |∂|V_i|/∂Q_j|", check=_rho),
    Option(
        "rounds",
        0,
        "end-to-end rounds: refit on the voltages the rule produces in closed loop on the training period",
        check=_rounds,
    ),
    Option(
        "comply",
        True,
        "keep the voltage band: while the fitted rule leaves it in closed loop on the training period, refit to the "
        "optimum with the band tightened by 0.0025 … 0.05 p.u. (false: fit the optimum itself)",
    ),
)


def _learned(name: str, summary: str, reads: tuple[str, ...], check: Callable[[dict], None], *extra: Option):
    """A learned family's registration: slope-bounded, closed loop, fitted by `fit_configuration`."""
    return local_rule(
        name,
        reads=reads,
        options=(*LEARNED_OPTIONS, *extra),
        summary=summary + " (slope-bounded), closed loop",
        check=check,
        fit=fit_configuration,
        snapshot_wise=True,
    )


@_learned(
    "learned-affine",
    "learned linear decision rule Q/S̄ = a + b·P/S̄ + c·|V| + d·Q_load/S̄ per DER (c ≤ 0), fitted to the AC OPF",
    ("v", "p", "load"),
    check_affine,
)
def affine_target(
    m: Measured, train: str = "", params: str = "", rho: float = RHO, rounds: int = 0, comply: bool = True
) -> np.ndarray:
    """learned-affine's Q target (S, n_der) MVAr (module docstring)."""
    return _target(AffineRule.name, m, train, params)


@_learned(
    "learned-vv",
    "learned Volt-VAR: monotone piecewise-linear Q(|V|) per DER, knots at training-voltage quantiles, fitted to the AC OPF",
    ("v",),
    check_vv,
    Option("knots", KNOTS, "knots of the curve, at quantiles of the DER's training voltages"),
)
def vv_target(
    m: Measured, train: str = "", params: str = "", rho: float = RHO, rounds: int = 0, comply: bool = True, knots: int = KNOTS
) -> np.ndarray:
    """learned-vv's Q target (S, n_der) MVAr (module docstring)."""
    return _target(VoltVarRule.name, m, train, params)


@_learned(
    "learned-1547",
    "learned IEEE 1547 Volt-VAR: the four-point shape with per-DER points fitted to the AC OPF",
    ("v",),
    check_ieee1547,
)
def ieee1547_target(
    m: Measured, train: str = "", params: str = "", rho: float = RHO, rounds: int = 0, comply: bool = True
) -> np.ndarray:
    """learned-1547's Q target (S, n_der) MVAr (module docstring)."""
    return _target(Ieee1547Rule.name, m, train, params)
