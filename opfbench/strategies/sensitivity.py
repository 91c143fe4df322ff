"""The grid's voltage sensitivity at the DER buses, and the slope bound it gives a closed-loop
rule of |V|.

X = ∂|V|/∂Q (n_der × n_der, p.u. per MVAr): X_ij is how much the voltage magnitude at DER
i's bus changes per MVAr injected by DER j. It is measured by central finite differences
(±1 % of each DER's S̄) around a few no-action operating points — the snapshots of the
lowest, median and highest net load (load P minus DER P) — all in one batched power flow,
and the elementwise largest |X_ij| over those points is kept.

Why it bounds a rule's slope. A closed-loop rule of |V| sets Q_i = clip(f_i(|V_i|), ±L_i);
the grid answers |V| = g(Q). Its undamped iteration Q ↦ F(Q) = clip(f(g(Q))) has the
Jacobian diag(c)·X, c_i = f_i′. Clipping is 1-Lipschitz, so by the mean-value theorem

    |F_i(Q) − F_i(Q′)| ≤ |c_i|·|g_i(Q) − g_i(Q′)| ≤ |c_i|·Σ_j |X_ij|·‖Q − Q′‖∞,

and F is a contraction in the ∞-norm with factor ρ < 1 when every DER's largest |slope|
obeys |c_i|·Σ_j |X_ij| ≤ ρ, i.e. |c_i| ≤ ρ / R_i with the row sums R_i = Σ_j |X_ij|
(`slope_limit`, MVAr per p.u.). Then the steady state exists and is unique, the undamped
iteration reaches it, and so does the engine's damped one, Q += α·(F(Q) − Q), whose factor
is 1 − α·(1 − ρ) < 1. The bound is as good as X: exact to first order at the measured
operating points (X varies little over a feeder's operating range), not a certificate for
a grid whose impedances differ from the model's.
"""

from __future__ import annotations

import numpy as np

from opfbench.errors import InputError
from opfbench.powerflow import solve_pf_batch
from opfbench.scenario import Scenario

STEP_SHARE = 0.01  # the finite-difference step: 1 % of each DER's S̄
POINTS = 3  # operating points: lowest, median and highest net load


def operating_points(scenario: Scenario, points: int = POINTS) -> np.ndarray:
    """Row indices of `points` snapshots spread over the net load Σ load P − Σ DER P
    (lowest, highest and evenly spaced ranks in between), each once."""
    net_load = scenario.bus_load_mva().real.sum(axis=1) - scenario.der_p_mw.sum(axis=1)
    order = np.argsort(net_load, kind="stable")
    ranks = np.round(np.linspace(0, len(order) - 1, max(1, points))).astype(int)
    return np.unique(order[ranks])


def voltage_sensitivity(scenario: Scenario, rows: np.ndarray | None = None) -> np.ndarray:
    """X (n_der, n_der) p.u. per MVAr: the largest |∂|V_i|/∂Q_j| over the no-action
    operating points `rows` (default `operating_points`), by central differences of
    ±STEP_SHARE·S̄_j in one batched power flow. InputError where a flow does not converge."""
    net = scenario.net
    n_der = len(net.ders)
    rows = operating_points(scenario) if rows is None else np.asarray(rows, dtype=int)
    if n_der == 0:
        return np.zeros((0, 0))
    step = STEP_SHARE * net.der_s_mva
    dq = np.concatenate([np.diag(step), -np.diag(step)])  # (2 n_der, n_der): +δ_j, then −δ_j
    base = scenario.take(rows)
    zero = np.zeros((len(rows), n_der))
    inj = base.injections(zero)
    place = np.zeros((n_der, net.n_bus))
    place[np.arange(n_der), net.der_bus] = 1.0
    s = (inj[:, None, :] + 1j * (dq @ place)[None, :, :]).reshape(-1, net.n_bus)
    pf = solve_pf_batch(net, s)
    if not np.all(pf.converged):
        raise InputError(f"{net.name}: the power flow for the voltage sensitivity did not converge at every operating point")
    vm = np.abs(pf.v[:, net.der_bus]).reshape(len(rows), 2, n_der, n_der)  # point, sign, perturbed DER j, measured DER i
    x = (vm[:, 0] - vm[:, 1]) / (2 * step[None, :, None])  # (point, j, i)
    return np.abs(x).max(axis=0).T


def slope_limit(x: np.ndarray, rho: float) -> np.ndarray:
    """(n_der,) MVAr per p.u.: the largest |∂Q_i/∂|V_i|| of a contraction with factor `rho`,
    ρ / Σ_j |X_ij| (module docstring)."""
    if not 0 < rho < 1:
        raise InputError(f"the contraction factor rho must lie in (0, 1), got {rho:g}")
    return rho / np.abs(x).sum(axis=1)


def contraction_factor(x: np.ndarray, slope_mvar_per_pu: np.ndarray) -> float:
    """max_i |c_i|·Σ_j |X_ij|: the ∞-norm bound of diag(c)·X (< 1: a contraction)."""
    if slope_mvar_per_pu.size == 0:
        return 0.0
    return float((np.abs(slope_mvar_per_pu) * np.abs(x).sum(axis=1)).max())
