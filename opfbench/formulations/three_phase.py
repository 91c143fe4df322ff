"""The OPF problem on three-phase feeders: its exact model's optimum on every snapshot,
confirmed by the three-phase power flow — every reported figure is the power flow's — and
the relaxation's lower bound that certifies it. The models are the ones declared for the
feeder's class (`model.model_for(role, net)`: "unbalanced-radial" or "unbalanced-meshed";
today `models.ac_three_phase` exact on both, `models.sdp_three_phase` the relaxation on
radial feeders only — a meshed feeder gets no bound, refused with NetworkError).

`bound` solves the relaxation per snapshot (compiled once); `certify` compares: a step is
certified when the optimum's losses are within `CERTIFY_RTOL` (relative) of the bound,
otherwise its gap is recorded; a step whose relaxation is infeasible is proven infeasible.

Per snapshot (`optimum`): the exact model warm from the previous snapshot's answer, then
cold from the power flow's no-action point; a point is accepted only when IPOPT converged
and the power flow at its Q setpoints converges, meets the band (`BAND_TOL`) and gives the
model's losses within `CONFIRM_RTOL`. Otherwise the snapshot falls back to no action
(Q = 0) where that meets the band (status fallback-no-action), else reports `infeasible`
(IPOPT detected it: a local verdict) or `solver-failed`, with no figure. A snapshot where
no DER has Q to give (night, or k = 1) has one operating point, the power flow's: the
optimum where it meets the band, proven infeasible where it does not (`proven`).

Units: MW, MVAr (Q positive = injected), losses in kW.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.capability import check_reserve, qmax
from opfbench.formulations.model import load_models, model_for
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import solve_phase_flow
from opfbench.result import FALLBACK_COLD, FALLBACK_NO_ACTION, INFEASIBLE, OK, SOLVER_FAILED

CERTIFY_RTOL = 1e-6
"""An optimum within this (relative) of the relaxation's bound is certified."""
CONFIRM_RTOL = 1e-4
"""A model's point is accepted when the power flow's losses at its setpoints are within this
(relative) of the model's own: the two model the same feeder (the NLP's own point carries
IPOPT's constraint tolerance, which near-zero-impedance switches and regulators amplify;
the reported losses are the power flow's, at the NLP's setpoints)."""
BAND_TOL = 1e-6
"""p.u. by which an accepted point's monitored voltages may leave the band (round-off)."""


@dataclass(frozen=True, eq=False)
class PhaseOptimum:
    """The OPF on S snapshots. Arrays (S,): `status` (opfbench.result statuses),
    `losses_kw` the power flow's at the reported setpoints (NaN where there is no
    operating point to report), `objective_kw` the exact model's optimum (NaN unless
    accepted), `proven` (an infeasible snapshot proven so, module docstring),
    `iterations` and `solve_ms` (IPOPT's, summed over attempts), `vmin`/`vmax` (p.u., the
    monitored voltages; NaN with the losses); `q_mvar` (S, n_der) the setpoints (0 where
    there is no optimum)."""

    status: np.ndarray
    q_mvar: np.ndarray
    losses_kw: np.ndarray
    objective_kw: np.ndarray
    proven: np.ndarray
    iterations: np.ndarray
    solve_ms: np.ndarray
    vmin: np.ndarray
    vmax: np.ndarray


def q_limits(net: PhaseNetwork, der_p_mw: np.ndarray, k: float) -> np.ndarray:
    """(S, n_der) the usable |Q| (MVAr): (1 − k) × each unit's capability at its P."""
    check_reserve(k)
    if not net.ders:
        return np.zeros((der_p_mw.shape[0], 0))
    rating = np.array([d.rating_mw for d in net.ders])
    s = np.array([d.s_rated_mva for d in net.ders])
    return (1.0 - k) * qmax([d.kind for d in net.ders], der_p_mw, rating, s)


def optimum(
    net: PhaseNetwork,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    k: float = 0.0,
) -> PhaseOptimum:
    """The OPF on S snapshots (module docstring): load P and Q (S, n_load) at their law's
    reference, DER P (S, n_der), reserve k. Checked before any work: k, then shapes and
    finite values (the power flow's checks)."""
    check_reserve(k)
    no_action = solve_phase_flow(net, load_p_mw, load_q_mvar, der_p_mw)  # checks shapes and values first
    n, n_der = no_action.n_snapshots, len(net.ders)
    load_p, load_q = (np.asarray(x, dtype=float).reshape(n, net.n_load) for x in (load_p_mw, load_q_mvar))
    der_p = np.asarray(der_p_mw, dtype=float).reshape(n, n_der)
    limit = q_limits(net, der_p, k)
    load_models()
    exact = model_for("exact", net).build(net, True)
    lo, hi = net.band
    status = np.empty(n, dtype=object)
    q = np.zeros((n, n_der))
    objective = np.full(n, np.nan)
    iterations = np.zeros(n, dtype=int)
    solve_ms = np.zeros(n)
    proven = np.zeros(n, dtype=bool)
    start = None
    in_band = no_action.converged & (lo - BAND_TOL <= no_action.vm.min(axis=1)) & (no_action.vm.max(axis=1) <= hi + BAND_TOL)
    for i in range(n):
        if not limit[i].any() and no_action.converged[i]:  # no decision: the power flow's point is the only one
            status[i] = OK if in_band[i] else INFEASIBLE
            objective[i] = no_action.losses_kw[i] if in_band[i] else np.nan
            proven[i] = not in_band[i]
            continue
        attempts, accepted = [], None
        if start is not None:
            attempts.append(exact.solve(load_p[i], load_q[i], der_p[i], limit[i], start=start))
            accepted = attempts[-1] if _accepted(net, attempts[-1], load_p[i], load_q[i], der_p[i]) else None
        if accepted is None and no_action.converged[i]:
            attempts.append(exact.solve(load_p[i], load_q[i], der_p[i], limit[i], x0=exact.initial(no_action.v[i])))
            accepted = attempts[-1] if _accepted(net, attempts[-1], load_p[i], load_q[i], der_p[i]) else None
        iterations[i] = sum(a.iterations for a in attempts)
        solve_ms[i] = sum(a.solve_ms for a in attempts)
        if accepted is not None:
            start = accepted
            q[i], objective[i] = accepted.q_pu, accepted.objective_kw
            status[i] = OK if accepted is attempts[0] else FALLBACK_COLD
        elif in_band[i]:
            status[i] = FALLBACK_NO_ACTION
        elif any(a.infeasible for a in attempts):
            status[i] = INFEASIBLE
        else:
            status[i] = SOLVER_FAILED
    flow = solve_phase_flow(net, load_p, load_q, der_p, q)
    settled = flow.converged & (status != INFEASIBLE) & (status != SOLVER_FAILED)
    return PhaseOptimum(
        status,
        q,
        np.where(settled, flow.losses_kw, np.nan),
        objective,
        proven,
        iterations,
        solve_ms,
        np.where(settled, flow.vm.min(axis=1, initial=np.inf), np.nan),
        np.where(settled, flow.vm.max(axis=1, initial=-np.inf), np.nan),
    )


def _accepted(net: PhaseNetwork, solve, load_p: np.ndarray, load_q: np.ndarray, der_p: np.ndarray) -> bool:
    """IPOPT converged, and the power flow at the solve's setpoints converges, meets the
    band and gives the model's losses within CONFIRM_RTOL."""
    if not solve.success or not np.isfinite(solve.objective_kw) or not np.all(np.isfinite(solve.q_pu)):
        return False
    flow = solve_phase_flow(net, load_p[None], load_q[None], der_p[None], solve.q_pu[None])
    if not flow.converged[0]:
        return False
    lo, hi = net.band
    within = lo - BAND_TOL <= flow.vm[0].min() and flow.vm[0].max() <= hi + BAND_TOL
    return bool(within and abs(flow.losses_kw[0] - solve.objective_kw) <= CONFIRM_RTOL * abs(flow.losses_kw[0]))


@dataclass(frozen=True, eq=False)
class PhaseBound:
    """The relaxation on S snapshots. Arrays (S,): `bound_kw` (NaN unless solved),
    `rank_ratio` (the largest second-to-first eigenvalue ratio over its PSD blocks),
    `rank_one` (every block rank one: `rank_ratio` ≤ the model's threshold), `infeasible`
    (the solver certified the relaxation, hence the OPF, infeasible), `status` (the
    solver's), `solve_ms` (per step); `compile_ms` the model's build plus first solve
    (cvxpy compiles there) less that solve's own time."""

    bound_kw: np.ndarray
    rank_ratio: np.ndarray
    rank_one: np.ndarray
    infeasible: np.ndarray
    status: np.ndarray
    solve_ms: np.ndarray
    compile_ms: float


def bound(
    net: PhaseNetwork,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    k: float = 0.0,
) -> PhaseBound:
    """The relaxation's bound on S snapshots (arguments as `optimum`); NetworkError where no
    relaxation serves the feeder (meshed). Checked before any work: k, the model, then
    shapes and finite values (the power flow's checks, on the first snapshot)."""
    import time

    check_reserve(k)
    load_models()
    spec = model_for("relaxation", net)
    solve_phase_flow(net, load_p_mw, load_q_mvar, der_p_mw)  # checks shapes and values first
    load_p, load_q = (np.asarray(x, dtype=float).reshape(-1, net.n_load) for x in (load_p_mw, load_q_mvar))
    der_p = np.asarray(der_p_mw, dtype=float).reshape(len(load_p), len(net.ders))
    limit = q_limits(net, der_p, k)
    start = time.perf_counter()
    model = spec.build(net, True)
    solves = []
    for i in range(len(load_p)):
        solves.append(model.solve(load_p[i], load_q[i], der_p[i], limit[i]))
        if i == 0:
            compile_ms = (time.perf_counter() - start) * 1e3 - solves[0].solve_ms
    if not solves:
        compile_ms = (time.perf_counter() - start) * 1e3

    def field(name: str, dtype: type) -> np.ndarray:
        return np.array([getattr(s, name) for s in solves], dtype=dtype)

    return PhaseBound(
        field("bound_kw", float),
        field("rank_ratio", float),
        field("rank_one", bool),
        field("infeasible", bool),
        field("status", object),
        field("solve_ms", float),
        compile_ms,
    )


def certify(opt: PhaseOptimum, relaxed: PhaseBound) -> tuple[np.ndarray, np.ndarray]:
    """(certified, gap) per snapshot: the gap (optimum's losses − bound) / optimum's losses
    where both exist (NaN elsewhere); certified where that gap is within CERTIFY_RTOL."""
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = (opt.losses_kw - relaxed.bound_kw) / np.abs(opt.losses_kw)
    return np.isfinite(gap) & (np.abs(gap) <= CERTIFY_RTOL), gap
