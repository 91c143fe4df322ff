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

from opfbench.formulations.models.distflow import RadialBranches
from opfbench.formulations.problem import SLACK_P_TOLERANCE, VOLTAGE_TOLERANCE, OpfProblem, SnapshotData

ROUNDS = 2  # up-and-down passes
MARGIN = 1e-6  # p.u. (power) and p.u.² (squared voltage) beyond a limit a proof needs
# The reasons, as a snapshot's solver_status reads them
SLACK_MUST_EXPORT = "bounds: the slack must export"
VOLTAGES_OUT_OF_REACH = "bounds: voltage limits out of reach"


def _scaled(coef: np.ndarray | float, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interval of coef·y for y in [lo, hi] (elementwise, any sign of coef)."""
    a, b = coef * lo, coef * hi
    return np.minimum(a, b), np.maximum(a, b)


def _square(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interval of y² for y in [lo, hi]."""
    nearest = np.maximum(np.maximum(lo, -hi), 0.0)
    return nearest**2, np.maximum(lo**2, hi**2)


@dataclass(frozen=True)
class FlowBounds:
    """Per snapshot (module docstring): slack_p_hi (S,) an upper bound on the slack's P
    (p.u., positive = import); v_lo, v_hi (S, n_bus) the squared-voltage intervals left
    (p.u.²); out_of_reach (S,) bool: some bus's interval is empty."""

    slack_p_hi: np.ndarray
    v_lo: np.ndarray
    v_hi: np.ndarray
    out_of_reach: np.ndarray


class _Passes:
    """The up and down passes over one feeder's branches for all snapshots at once; every
    per-bus array is (n_bus, S), a bus's snapshots contiguous."""

    def __init__(self, problem: OpfProblem, data: SnapshotData):
        self.problem, self.br = problem, RadialBranches.of(problem.net)
        self.p_fixed = np.ascontiguousarray(data.s_fixed.real.T)
        self.q_fixed = np.ascontiguousarray(data.s_fixed.imag.T)
        self.q_der = problem.der_at_bus @ data.q_limit.T  # Σ usable |Q| of the DER at each bus
        self.g = problem.gsh + self.br.conductance  # P drawn by a bus's shunts per p.u.² of v
        self.b = problem.bsh + self.br.charging  # Q they inject
        m, s = self.br.child.size, data.n_snapshots
        # per branch (rows) and snapshot: the interval of r·P + x·Q at the sending end and of ℓ
        self.drop_lo, self.drop_hi = np.empty((m, s)), np.empty((m, s))
        self.l_lo, self.l_hi = np.empty((m, s)), np.empty((m, s))

    def up(self, v_lo: np.ndarray, v_hi: np.ndarray) -> np.ndarray:
        """Leaves first: the branches' intervals (kept for `down`); returns slack_p_hi."""
        br = self.br
        p_lo, p_hi = np.zeros_like(v_lo), np.zeros_like(v_lo)  # what a bus sends to its children
        q_lo, q_hi = np.zeros_like(v_lo), np.zeros_like(v_lo)
        for k in range(br.child.size - 1, -1, -1):
            j, parent = br.child[k], br.parent[k]
            gv_lo, gv_hi = _scaled(self.g[j], v_lo[j], v_hi[j])
            bv_lo, bv_hi = _scaled(self.b[j], v_lo[j], v_hi[j])
            pj_lo = p_lo[j] + gv_lo - self.p_fixed[j]
            pj_hi = p_hi[j] + gv_hi - self.p_fixed[j]
            qj_lo = q_lo[j] - bv_hi - self.q_fixed[j] - self.q_der[j]
            qj_hi = q_hi[j] - bv_lo - self.q_fixed[j] + self.q_der[j]
            (pp_lo, pp_hi), (qq_lo, qq_hi) = _square(pj_lo, pj_hi), _square(qj_lo, qj_hi)
            w_lo, w_hi = v_lo[j] * br.child_scale[k], v_hi[j] * br.child_scale[k]
            l_lo = (pp_lo + qq_lo) / w_hi
            l_hi = np.where(pp_hi + qq_hi > 0, (pp_hi + qq_hi) / w_lo, 0.0)
            xl_lo, xl_hi = _scaled(br.x[k], l_lo, l_hi)
            ps_lo, ps_hi = pj_lo + br.r[k] * l_lo, pj_hi + br.r[k] * l_hi  # r ≥ 0 (`Network` checks it)
            qs_lo, qs_hi = qj_lo + xl_lo, qj_hi + xl_hi
            xq_lo, xq_hi = _scaled(br.x[k], qs_lo, qs_hi)
            self.drop_lo[k], self.drop_hi[k] = br.r[k] * ps_lo + xq_lo, br.r[k] * ps_hi + xq_hi
            self.l_lo[k], self.l_hi[k] = l_lo, l_hi
            p_lo[parent] += ps_lo
            p_hi[parent] += ps_hi
            q_lo[parent] += qs_lo
            q_hi[parent] += qs_hi
        slack = self.problem.slack
        return p_hi[slack] + _scaled(self.g[slack], v_lo[slack], v_hi[slack])[1] - self.p_fixed[slack]

    def down(self, v_lo: np.ndarray, v_hi: np.ndarray, lim_lo: np.ndarray, lim_hi: np.ndarray) -> np.ndarray:
        """Parents first: each v's interval from its parent's and its branch's, intersected
        with the limits in place; returns which snapshots got an empty one (beyond MARGIN)."""
        br = self.br
        empty = np.zeros(v_lo.shape[1], dtype=bool)
        for k in range(br.child.size):
            j, parent, z2 = br.child[k], br.parent[k], br.r[k] ** 2 + br.x[k] ** 2
            lo = (v_lo[parent] * br.parent_scale[k] - 2 * self.drop_hi[k] + z2 * self.l_lo[k]) / br.child_scale[k]
            hi = (v_hi[parent] * br.parent_scale[k] - 2 * self.drop_lo[k] + z2 * self.l_hi[k]) / br.child_scale[k]
            empty |= (lo > lim_hi[j] + MARGIN) | (hi < lim_lo[j] - MARGIN)
            v_lo[j] = np.maximum(np.minimum(lo, lim_hi[j]), lim_lo[j])
            v_hi[j] = np.minimum(np.maximum(hi, lim_lo[j]), lim_hi[j])
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
