"""An upper bound on the slack bus's active import over every AC operating point of a
radial feeder within its voltage limits — a sound and cheap proof that the paper's OPF
setup (the slack may not export, `OpfProblem.slack_export` False) is infeasible.

Why a bound and not a relaxation: where the DER surplus exceeds what the feeder can lose,
every AC point has the slack exporting, yet the SOCP relaxation stays feasible — it may
burn the surplus in losses no AC point has (ℓ above (P² + Q²)/v). No convex relaxation
can do better in general: a convex combination of the normal power-flow solution with the
high-current ("low-voltage") one meets every linear constraint, keeps the voltages within
their limits for small weights and imports through the slack. What excludes the
high-current points is the lower voltage limit at the receiving end of each branch, which
this bound uses directly.

The argument, in DistFlow's exact branch-flow form (`models.distflow.RadialBranches`,
p.u.): for the branch into bus j, the power that reaches j's end of its series impedance,
S'_j = P'_j + j·Q'_j, is what j's subtree takes:

    P'_j = Σ_children c (P'_c + r_c·ℓ_c) + (gsh_j + g_j)·v_j − p_fixed_j
    Q'_j = Σ_children c (Q'_c + x_c·ℓ_c) − (bsh_j + b_j)·v_j − q_fixed_j − Q_DER,j

and at every AC point the squared series current is ℓ_j = |S'_j|² / w_j, w_j = v_j (÷ τ²
when j is the branch's from end). From the leaves up, intervals on P'_j, Q'_j (DER Q within
±q_limit, v_j within [vmin − tol, vmax + tol]², the children's intervals) bound |S'_j|², and
with w_j ≥ (vmin_j − tol)² they bound ℓ_j; the slack's import is

    P_slack = Σ_children c of the slack (P'_c + r_c·ℓ_c) + (gsh + g)_slack·v_slack² − p_fixed_slack,

bounded above by the same intervals. Where that bound is below −SLACK_P_TOLERANCE every
point meeting the voltage limits (to VOLTAGE_TOLERANCE) has the slack exporting beyond
what `OpfProblem.feasible` accepts: the problem is infeasible, and so is no action.
Rounding is negligible against that margin (≥ 1e-8 p.u. on any base up to 100 MVA).

`slack_import_bound` is vectorised over snapshots (one pass over the buses); meshed feeders
get no bound (+inf).
"""

from __future__ import annotations

import numpy as np

from opfbench.formulations.models.distflow import RadialBranches
from opfbench.formulations.problem import SLACK_P_TOLERANCE, VOLTAGE_TOLERANCE, OpfProblem, SnapshotData


def _scaled(coef: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interval of coef·y for y in [lo, hi] (elementwise, any sign of coef)."""
    a, b = coef * lo, coef * hi
    return np.minimum(a, b), np.maximum(a, b)


def _square(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interval of y² for y in [lo, hi]."""
    nearest = np.maximum(np.maximum(lo, -hi), 0.0)
    return nearest**2, np.maximum(lo**2, hi**2)


def slack_import_bound(problem: OpfProblem, data: SnapshotData) -> np.ndarray:
    """(S,) p.u.: an upper bound on the slack bus's active injection into the feeder
    (positive = import) over every AC point of each snapshot with every non-slack |V| in
    [vmin − VOLTAGE_TOLERANCE, vmax + VOLTAGE_TOLERANCE] and every DER Q within
    ±q_limit (module docstring); +inf on a meshed feeder."""
    net = problem.net
    n_snap = data.n_snapshots
    if net.meshed:
        return np.full(n_snap, np.inf)
    br = RadialBranches.of(net)
    vm_lo = np.maximum(net.vmin - VOLTAGE_TOLERANCE, 0.0)
    v_lo, v_hi = vm_lo**2, (net.vmax + VOLTAGE_TOLERANCE) ** 2
    v_lo[problem.slack] = v_hi[problem.slack] = problem.v_slack**2
    shunt_p = _scaled(problem.gsh + br.conductance, v_lo, v_hi)  # (n_bus,) intervals of the P drawn by shunts
    shunt_q = _scaled(problem.bsh + br.charging, v_lo, v_hi)  # and of the Q they inject
    q_der = data.q_limit @ problem.der_at_bus.T.toarray()  # (S, n_bus) Σ usable |Q| of the DER at each bus
    # Per bus: the intervals of P and Q it sends into its branches to the children.
    p_lo, p_hi = np.zeros((n_snap, net.n_bus)), np.zeros((n_snap, net.n_bus))
    q_lo, q_hi = np.zeros((n_snap, net.n_bus)), np.zeros((n_snap, net.n_bus))
    p_fixed, q_fixed = data.s_fixed.real, data.s_fixed.imag
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in range(br.child.size - 1, -1, -1):  # children before parents
            j, parent = br.child[k], br.parent[k]
            pj_lo = p_lo[:, j] + shunt_p[0][j] - p_fixed[:, j]
            pj_hi = p_hi[:, j] + shunt_p[1][j] - p_fixed[:, j]
            qj_lo = q_lo[:, j] - shunt_q[1][j] - q_fixed[:, j] - q_der[:, j]
            qj_hi = q_hi[:, j] - shunt_q[0][j] - q_fixed[:, j] + q_der[:, j]
            (pp_lo, pp_hi), (qq_lo, qq_hi) = _square(pj_lo, pj_hi), _square(qj_lo, qj_hi)
            w_lo, w_hi = v_lo[j] * br.child_scale[k], v_hi[j] * br.child_scale[k]
            l_lo, l_hi = (pp_lo + qq_lo) / w_hi, np.where(pp_hi + qq_hi > 0, (pp_hi + qq_hi) / w_lo, 0.0)
            xl_lo, xl_hi = _scaled(br.x[k], l_lo, l_hi)
            p_lo[:, parent] += pj_lo + br.r[k] * l_lo  # r ≥ 0 (`Network` checks it)
            p_hi[:, parent] += pj_hi + br.r[k] * l_hi
            q_lo[:, parent] += qj_lo + xl_lo
            q_hi[:, parent] += qj_hi + xl_hi
        bound = p_hi[:, problem.slack] + shunt_p[1][problem.slack] - p_fixed[:, problem.slack]
    return np.where(np.isnan(bound), np.inf, bound)


def slack_must_export(problem: OpfProblem, data: SnapshotData) -> np.ndarray:
    """(S,) bool: the snapshots that the bound proves infeasible under the slack rule (no AC
    point within the limits lets the slack import, or export less than SLACK_P_TOLERANCE
    MW); all False when the slack may export."""
    if problem.slack_export:
        return np.zeros(data.n_snapshots, dtype=bool)
    return slack_import_bound(problem, data) < -SLACK_P_TOLERANCE / problem.net.base_mva
