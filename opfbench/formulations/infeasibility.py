"""Sound and cheap proofs that the AC OPF has no feasible point on a radial feeder: interval
bounds on DistFlow's exact branch-flow equations, valid at every AC operating point within
the limits.

Why bounds and not a relaxation: the SOCP relaxation stays feasible at many AC-infeasible
snapshots of DER-rich feeders — it may burn power in losses no AC point has (ℓ above
(P² + Q²)/v), which lets the slack import under the paper's rule (slack P ≥ 0) and drags
voltages down to their upper limits. No convex relaxation can do better in general: a
convex combination of the normal power-flow solution with the high-current ("low-voltage")
one meets every linear constraint and keeps the voltages within their limits for small
weights. What excludes the high-current points is the lower voltage limit at the
receiving end of each branch, which these bounds use directly.

The equations (`models.distflow.RadialBranches`, p.u.; exact at every AC point of a radial
feeder). For the branch k into bus j from its parent i, S'_j = P'_j + j·Q'_j is the power
that reaches j's end of the series impedance r + jx — what j's subtree takes:

    P'_j = Σ_children c (P'_c + r_c·ℓ_c) + (gsh_j + g_j)·v_j − p_fixed_j
    Q'_j = Σ_children c (Q'_c + x_c·ℓ_c) − (bsh_j + b_j)·v_j − q_fixed_j − Q_DER,j
    ℓ_k  = |S'_j|² / (v_j·cs_k)                                    (squared series current)
    v_j·cs_k = v_i·ps_k − 2·(r·P_k + x·Q_k) + (r² + x²)·ℓ_k,   P_k + j·Q_k = S'_j + (r + jx)·ℓ_k

with v = |V|², cs/ps the 1/τ² of a tap at the branch's from end, and at the slack
P_slack = Σ_children c (P'_c + r_c·ℓ_c) + (gsh + g)_slack·v_slack² − p_fixed_slack.

Interval arithmetic on them, given DER Q within ±q_limit and every non-slack v within
[(vmin − tol)², (vmax + tol)²] (tol = VOLTAGE_TOLERANCE): from the leaves up, intervals of
P', Q', ℓ and the sending-end flows of every branch, and of the slack's P; from the slack
down, the interval of each v implied by its parent's and the branch's, intersected with
its limits. An empty intersection proves the snapshot infeasible ("voltage limits out of
reach": e.g. a bus whose |V| limit is below what any operating point gives it); where the
slack may not export, so does an upper bound on P_slack below −SLACK_P_TOLERANCE ("the
slack must export": the DER surplus exceeds every loss the feeder can have). ROUNDS up
and down passes, the later ones on the narrowed voltages. Claims need MARGIN beyond the
limits, far above rounding and the power flow's mismatch: where a proof holds, the AC
evaluation of no action fails `OpfProblem.feasible` too.

Meshed feeders get no proof.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from opfbench.formulations.models.distflow import RadialBranches
from opfbench.formulations.problem import SLACK_P_TOLERANCE, VOLTAGE_TOLERANCE, OpfProblem, SnapshotData

ROUNDS = 2  # up-and-down passes
MARGIN = 1e-6  # p.u. (power) and p.u.² (squared voltage) beyond a limit a proof needs
# The reasons, as a snapshot's solver_status reads them
SLACK_MUST_EXPORT = "bounds: the slack must export"
VOLTAGES_OUT_OF_REACH = "bounds: voltage limits out of reach"


@dataclass(frozen=True)
class FlowBounds:
    """Per snapshot (module docstring): slack_p_hi (S,) an upper bound on the slack's P
    (p.u., positive = import); v_lo, v_hi (S, n_bus) the squared-voltage intervals left
    (p.u.²); out_of_reach (S,) bool: some bus's interval is empty."""

    slack_p_hi: np.ndarray
    v_lo: np.ndarray
    v_hi: np.ndarray
    out_of_reach: np.ndarray


@njit(inline="always")
def _min(a: float, b: float) -> float:
    """np.minimum of two floats: NaN if either is NaN; of two equal ones (±0) the second."""
    if a != a or b != b:
        return a + b
    return a if a < b else b


@njit(inline="always")
def _max(a: float, b: float) -> float:
    """np.maximum of two floats (as `_min`)."""
    if a != a or b != b:
        return a + b
    return a if a > b else b


@njit(inline="always")
def _scaled(coef: float, lo: float, hi: float) -> tuple[float, float]:
    """The interval of coef·y for y in [lo, hi] (any sign of coef)."""
    a, b = coef * lo, coef * hi
    return _min(a, b), _max(a, b)


@njit(inline="always")
def _square(lo: float, hi: float) -> tuple[float, float]:
    """The interval of y² for y in [lo, hi]."""
    nearest = _max(_max(lo, -hi), 0.0)
    return nearest * nearest, _max(lo * lo, hi * hi)


@njit(cache=True, error_model="numpy")
def _up(child, parent, r, x, child_scale, g, b, p_fixed, q_fixed, q_der, v_lo, v_hi, drop_lo, drop_hi, l_lo, l_hi, p_hi):
    """Leaves first, every snapshot (columns): the branches' intervals into drop_lo, drop_hi
    (r·P + x·Q at the sending end) and l_lo, l_hi (ℓ), each bus's upper bound on the P it
    sends to its children into p_hi. Per-bus arrays (n_bus, S), per-branch (m, S)."""
    n_snap = v_lo.shape[1]
    p_lo, q_lo, q_hi = np.zeros_like(v_lo), np.zeros_like(v_lo), np.zeros_like(v_lo)
    p_hi[:] = 0.0
    for k in range(child.size - 1, -1, -1):
        j, up = child[k], parent[k]
        for t in range(n_snap):
            gv_lo, gv_hi = _scaled(g[j], v_lo[j, t], v_hi[j, t])
            bv_lo, bv_hi = _scaled(b[j], v_lo[j, t], v_hi[j, t])
            pj_lo = p_lo[j, t] + gv_lo - p_fixed[j, t]
            pj_hi = p_hi[j, t] + gv_hi - p_fixed[j, t]
            qj_lo = q_lo[j, t] - bv_hi - q_fixed[j, t] - q_der[j, t]
            qj_hi = q_hi[j, t] - bv_lo - q_fixed[j, t] + q_der[j, t]
            pp_lo, pp_hi = _square(pj_lo, pj_hi)
            qq_lo, qq_hi = _square(qj_lo, qj_hi)
            w_lo, w_hi = v_lo[j, t] * child_scale[k], v_hi[j, t] * child_scale[k]
            ll_lo = (pp_lo + qq_lo) / w_hi
            ll_hi = (pp_hi + qq_hi) / w_lo if pp_hi + qq_hi > 0 else 0.0
            xl_lo, xl_hi = _scaled(x[k], ll_lo, ll_hi)
            ps_lo, ps_hi = pj_lo + r[k] * ll_lo, pj_hi + r[k] * ll_hi  # r ≥ 0 (`Network` checks it)
            qs_lo, qs_hi = qj_lo + xl_lo, qj_hi + xl_hi
            xq_lo, xq_hi = _scaled(x[k], qs_lo, qs_hi)
            drop_lo[k, t], drop_hi[k, t] = r[k] * ps_lo + xq_lo, r[k] * ps_hi + xq_hi
            l_lo[k, t], l_hi[k, t] = ll_lo, ll_hi
            p_lo[up, t] += ps_lo
            p_hi[up, t] += ps_hi
            q_lo[up, t] += qs_lo
            q_hi[up, t] += qs_hi


@njit(cache=True, error_model="numpy")
def _down(child, parent, z2, parent_scale, child_scale, drop_lo, drop_hi, l_lo, l_hi, lim_lo, lim_hi, v_lo, v_hi, empty):
    """Parents first: each v's interval from its parent's and its branch's, intersected
    with the limits in place; `empty` |= the snapshots that got an empty one (beyond MARGIN)."""
    for k in range(child.size):
        j, up = child[k], parent[k]
        for t in range(v_lo.shape[1]):
            lo = (v_lo[up, t] * parent_scale[k] - 2.0 * drop_hi[k, t] + z2[k] * l_lo[k, t]) / child_scale[k]
            hi = (v_hi[up, t] * parent_scale[k] - 2.0 * drop_lo[k, t] + z2[k] * l_hi[k, t]) / child_scale[k]
            empty[t] |= (lo > lim_hi[j] + MARGIN) | (hi < lim_lo[j] - MARGIN)
            v_lo[j, t] = _max(_min(lo, lim_hi[j]), lim_lo[j])
            v_hi[j, t] = _min(_max(hi, lim_lo[j]), lim_hi[j])


class _Passes:
    """The up and down passes over one feeder's branches for all snapshots at once (compiled:
    the branches in order, each over every snapshot, the arithmetic numpy's operation for
    operation); every per-bus array is (n_bus, S), a bus's snapshots contiguous."""

    def __init__(self, problem: OpfProblem, data: SnapshotData):
        self.problem, self.br = problem, RadialBranches.of(problem.net)
        br = self.br
        self.p_fixed = np.ascontiguousarray(data.s_fixed.real.T)
        self.q_fixed = np.ascontiguousarray(data.s_fixed.imag.T)
        self.q_der = np.ascontiguousarray(problem.der_at_bus @ data.q_limit.T)  # Σ usable |Q| of the DER at each bus
        self.g = problem.gsh + br.conductance  # P drawn by a bus's shunts per p.u.² of v
        self.b = problem.bsh + br.charging  # Q they inject
        self.z2 = np.array([br.r[k] ** 2 + br.x[k] ** 2 for k in range(br.child.size)])
        m, s = br.child.size, data.n_snapshots
        # per branch (rows) and snapshot: the interval of r·P + x·Q at the sending end and of ℓ
        self.drop_lo, self.drop_hi = np.empty((m, s)), np.empty((m, s))
        self.l_lo, self.l_hi = np.empty((m, s)), np.empty((m, s))

    def up(self, v_lo: np.ndarray, v_hi: np.ndarray) -> np.ndarray:
        """Leaves first: the branches' intervals (kept for `down`); returns slack_p_hi."""
        br, p_hi = self.br, np.empty_like(v_lo)
        passes = (self.drop_lo, self.drop_hi, self.l_lo, self.l_hi)
        _up(
            br.child,
            br.parent,
            br.r,
            br.x,
            br.child_scale,
            self.g,
            self.b,
            self.p_fixed,
            self.q_fixed,
            self.q_der,
            v_lo,
            v_hi,
            *passes,
            p_hi,
        )
        slack, g = self.problem.slack, self.g[self.problem.slack]
        return p_hi[slack] + np.maximum(g * v_lo[slack], g * v_hi[slack]) - self.p_fixed[slack]

    def down(self, v_lo: np.ndarray, v_hi: np.ndarray, lim_lo: np.ndarray, lim_hi: np.ndarray) -> np.ndarray:
        """Parents first (`_down`); returns which snapshots got an empty interval."""
        br = self.br
        empty = np.zeros(v_lo.shape[1], dtype=bool)
        passes = (self.drop_lo, self.drop_hi, self.l_lo, self.l_hi)
        _down(br.child, br.parent, self.z2, br.parent_scale, br.child_scale, *passes, lim_lo, lim_hi, v_lo, v_hi, empty)
        return empty


def flow_bounds(problem: OpfProblem, data: SnapshotData) -> FlowBounds:
    """The bounds of every snapshot of `data` (module docstring); the feeder must be radial."""
    net = problem.net
    lim_lo = np.maximum(net.vmin - VOLTAGE_TOLERANCE, 0.0) ** 2
    lim_hi = (net.vmax + VOLTAGE_TOLERANCE) ** 2
    lim_lo[problem.slack] = lim_hi[problem.slack] = problem.v_slack**2
    v_lo = np.repeat(lim_lo[:, None], data.n_snapshots, axis=1)  # (n_bus, S)
    v_hi = np.repeat(lim_hi[:, None], data.n_snapshots, axis=1)
    passes = _Passes(problem, data)
    empty = np.zeros(data.n_snapshots, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # vmin 0: ℓ unbounded
        for _ in range(ROUNDS):
            slack_p_hi = passes.up(v_lo, v_hi)
            empty |= passes.down(v_lo, v_hi, lim_lo, lim_hi)
    return FlowBounds(np.where(np.isnan(slack_p_hi), np.inf, slack_p_hi), v_lo.T, v_hi.T, empty)


def proven_infeasible(problem: OpfProblem, data: SnapshotData) -> np.ndarray:
    """(S,) per snapshot the reason the bounds prove it infeasible (VOLTAGES_OUT_OF_REACH,
    SLACK_MUST_EXPORT — the latter only where the slack may not export), "" where they do
    not; all "" on a meshed feeder."""
    reasons = np.full(data.n_snapshots, "", dtype=object)
    if problem.net.meshed:
        return reasons
    bounds = flow_bounds(problem, data)
    if not problem.slack_export:
        limit = -SLACK_P_TOLERANCE / problem.net.base_mva - MARGIN
        reasons[bounds.slack_p_hi < limit] = SLACK_MUST_EXPORT
    reasons[bounds.out_of_reach] = VOLTAGES_OUT_OF_REACH
    return reasons
