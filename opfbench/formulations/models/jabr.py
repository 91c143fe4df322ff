"""Jabr's bus-injection SOC relaxation, any feeder (radial or meshed).

W = V·Vᴴ on the branches: v_i = W_ii, c + js = W_ft; the flows are linear in (v, c, s)
for the general π model with taps and phase shifts (`problem.PiBranches`), relaxed by
c² + s² ≤ v_f·v_t (the angle-cycle conditions of meshes are dropped).

Cone residual (`relaxation_gap`): v_f·v_t − c² − s², the squared voltage-product
magnitude (on a meshed feeder also the cycle condition would have to hold for the
relaxation to be exact).
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from opfbench.formulations.model import formulation
from opfbench.formulations.models.conic import ConicModel, Reader


@formulation(
    "jabr",
    role="relaxation",
    networks=("radial", "meshed"),
    serves_problem=True,
    preference=1,  # on a radial feeder DistFlow serves: its cones are the branches' own
    summary="Jabr's bus-injection SOC relaxation (any feeder)",
)
class JabrSocp(ConicModel):
    """Bus-injection (Jabr) SOC relaxation for any feeder; see the module docstring."""

    def _network_model(self) -> tuple[cp.Expression, cp.Expression, cp.Expression, list[cp.Constraint]]:
        br = self.problem.branches
        self.c_br = cp.Variable(br.n_branch, name="c_branch")  # Re V_f·conj(V_t)
        self.s_br = cp.Variable(br.n_branch, name="s_branch")  # Im V_f·conj(V_t)
        vf, vt = self.v[br.f], self.v[br.t]
        p_f, q_f, p_t, q_t = br.flows(vf, vt, self.c_br, self.s_br, cp.multiply)
        mismatch_p = br.at_from @ p_f + br.at_to @ p_t + cp.multiply(self.problem.gsh, self.v) - self._p_fixed_bus()
        mismatch_q = (
            br.at_from @ q_f + br.at_to @ q_t - cp.multiply(self.problem.bsh, self.v) - self.q_fixed - self._der_q_at_buses()
        )
        cone = cp.SOC(vf + vt, cp.vstack([2 * self.c_br, 2 * self.s_br, vf - vt]), axis=0)
        return mismatch_p, mismatch_q, cp.sum(p_f + p_t), [cone]

    def _cone_residual(self, value: Reader) -> np.ndarray:
        br = self.problem.branches
        v = value(self.v)
        c, s = value(self.c_br), value(self.s_br)
        return np.max(v[:, br.f] * v[:, br.t] - c**2 - s**2, axis=1, initial=0.0)
