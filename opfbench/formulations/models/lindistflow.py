"""LinDistFlow: the linearized branch flow of a radial feeder (Baran–Wu), an approximation of
the OPF problem — fast, and neither a bound nor an optimum.

Per branch from parent i to child j, the flow P + jQ into the branch is what j's subtree
takes (the losses dropped from the balance), and the voltage drop is linear in it:

    v_j = v_i − 2·(r·P + x·Q)        (v = |V|², p.u.²)

with DistFlow's conventions for taps and π-model shunts (`distflow.RadialBranches`: a tap
scales its from end's v by 1/τ², line charging and shunt conductance sit at the buses).
The objective estimates the branch losses of those flows, Σ r·(P² + Q²)/v_slack² plus the
π-model shunt conductance's Σ g·v (kW on `net.base_mva`): a convex quadratic, which
Clarabel solves with its P matrix (`solvers.clarabel_adapter`). Its setpoints are
AC-evaluated like every formulation's; its objective is the estimate the report sets
against their AC losses.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from opfbench.formulations.model import formulation
from opfbench.formulations.models.conic import ConicModel, Reader
from opfbench.formulations.models.distflow import RadialBranches
from opfbench.formulations.problem import incidence


@formulation(
    "lindistflow",
    role="approximation",
    networks=("radial",),
    summary="LinDistFlow (Baran–Wu linearized branch flow, losses estimated as Σ r·(P² + Q²)): fast approximation; "
    "its Q evaluated by AC power flow",
)
class LinDistFlow(ConicModel):
    """LinDistFlow on a radial feeder; see the module docstring."""

    def _network_model(self) -> tuple[cp.Expression, cp.Expression, cp.Expression, list[cp.Constraint]]:
        net, problem = self.net, self.problem
        br = RadialBranches.of(net)
        n, m = net.n_bus, br.child.size
        at_child, at_parent = incidence(br.child, n), incidence(br.parent, n)
        self.p_br = cp.Variable(m, name="p_branch")
        self.q_br = cp.Variable(m, name="q_branch")
        v_parent, v_child = self.v[br.parent], self.v[br.child]
        if br.tapped:
            v_parent = cp.multiply(br.parent_scale, v_parent)
            v_child = cp.multiply(br.child_scale, v_child)
        self._shunt_g = problem.gsh + br.conductance
        self._from_slack = br.parent == net.slack
        mismatch_p = (at_parent - at_child) @ self.p_br + cp.multiply(self._shunt_g, self.v) - self.p_fixed
        mismatch_q = (
            (at_parent - at_child) @ self.q_br
            - cp.multiply(problem.bsh + br.charging, self.v)
            - self.q_fixed
            - self._der_q_at_buses()
        )
        drop = [v_child == v_parent - 2 * (cp.multiply(br.r, self.p_br) + cp.multiply(br.x, self.q_br))]
        weight = br.r / problem.v_slack**2
        losses = cp.sum(cp.multiply(weight, cp.square(self.p_br) + cp.square(self.q_br)))
        if br.conductance.any():
            losses = losses + br.conductance @ self.v
        return mismatch_p, mismatch_q, losses, drop

    def _slack_p_pu(self, value: Reader, thetas: np.ndarray, objective_kw: np.ndarray) -> np.ndarray:
        """The slack's mismatch (its P injection): the flows into its branches, plus its
        shunt's P, minus its fixed injection (the objective is not the balance's losses)."""
        slack = self.net.slack
        flows = value(self.p_br)[:, self._from_slack].sum(axis=1)
        return flows + self._shunt_g[slack] * value(self.v)[:, slack] - thetas[:, slack]
