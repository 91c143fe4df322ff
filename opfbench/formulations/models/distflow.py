"""DistFlow: the branch-flow SOC relaxation (Baran–Wu / Farivar–Low), radial feeders.

Per branch from parent i to child j: sending-end flow P + jQ into the series impedance
r + jx, squared series current ℓ; v_j = v_i − 2(rP + xQ) + (r² + x²)ℓ, and the relaxation
P² + Q² ≤ v_i·ℓ of P² + Q² = v_i·ℓ. Line charging b is exact as a shunt b/2 at both ends
(π model); bus shunts Gs/Bs exact. Transformers (real grids'): a tap ratio τ sits at the
branch's from end, so that end's voltage enters the branch as v/τ² (in the drop, the cone
and its shunts b/2, g/2 — the π model's shunt conductance g, e.g. iron losses, counted in
the losses like the series r·ℓ); a phase shift only rotates the angles of a radial
feeder, which DistFlow does not model, so it changes nothing. The cone is written per branch as
‖(2P/√α, 2Q/√α, v_i − ℓ/α)‖ ≤ v_i + ℓ/α, the same set for any α > 0, with α = (what the
branch may carry)² (`branch_scale`): ℓ/α is then of order one like v_i. Unscaled, a
branch carrying 1e-5 of a feeder's power has ℓ ~ 1e-10 next to v ~ 1 and Clarabel
stalls on large feeders, far from the optimum (`tests/test_formulations_scaling.py` shows
it on feeder10k, scaled and not).

Cone residual (`relaxation_gap`): v_i·ℓ − P² − Q², squared apparent power on base_mva.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from opfbench.errors import NetworkError
from opfbench.formulations.model import formulation
from opfbench.formulations.models.conic import ConicModel, Reader
from opfbench.formulations.problem import incidence
from opfbench.network import Network


@dataclass(frozen=True, eq=False)
class RadialBranches:
    """A radial feeder's in-service branches as DistFlow writes them: one per non-slack bus
    `child` (BFS order), from its `parent` through `branch`, series r + jx (p.u.); a tap τ
    scales the voltage of the branch's from end by 1/τ² (`parent_scale`, `child_scale`:
    1/τ² on the end that is the from end, else 1; all 1 without taps, `tapped` False);
    the π model's line charging b/2 and shunt conductance g/2 as bus shunts `charging`,
    `conductance` (n_bus,) p.u. at 1 p.u., from ends scaled by 1/τ² (module docstring)."""

    child: np.ndarray
    parent: np.ndarray
    branch: np.ndarray
    r: np.ndarray
    x: np.ndarray
    tapped: bool
    parent_scale: np.ndarray
    child_scale: np.ndarray
    charging: np.ndarray
    conductance: np.ndarray

    @classmethod
    def of(cls, net: Network) -> "RadialBranches":
        """The branches of `net`; NetworkError on a meshed feeder."""
        if net.meshed:
            raise NetworkError(f"{net.name}: DistFlow needs a radial feeder; this one is meshed (use the Jabr model)")
        on = np.flatnonzero(net.status)
        child = net.bfs_order[net.bfs_order != net.slack]
        parent, branch = net.parent[child], net.parent_branch[child]
        n, m = net.n_bus, child.size
        tapped = bool((net.tap[on] != 1.0).any())
        from_scale = 1.0 / net.tap[on] ** 2 if tapped else 1.0  # the from end's shunts see v/τ²
        charging = np.zeros(n)  # π-model line charging as bus shunts, b/2 at each end
        np.add.at(charging, net.f[on], net.b[on] / 2 * from_scale)
        np.add.at(charging, net.t[on], net.b[on] / 2)
        conductance = np.zeros(n)  # π-model shunt conductance g/2 at each end (branch losses)
        if net.g[on].any():
            np.add.at(conductance, net.f[on], net.g[on] / 2 * from_scale)
            np.add.at(conductance, net.t[on], net.g[on] / 2)
        if tapped:  # v/τ² at the from end of each branch (parent or child side)
            at_tap = 1.0 / net.tap[branch] ** 2
            from_is_parent = net.f[branch] == parent
            parent_scale, child_scale = np.where(from_is_parent, at_tap, 1.0), np.where(from_is_parent, 1.0, at_tap)
        else:
            parent_scale = child_scale = np.ones(m)
        return cls(child, parent, branch, net.r[branch], net.x[branch], tapped, parent_scale, child_scale, charging, conductance)


@formulation(
    "distflow",
    role="relaxation",
    networks=("radial",),
    serves_problem=True,
    summary="DistFlow branch-flow SOC relaxation (radial feeders)",
)
class DistFlowSocp(ConicModel):
    """Branch-flow (DistFlow) relaxation for radial feeders; see the module docstring."""

    def _network_model(self) -> tuple[cp.Expression, cp.Expression, cp.Expression, list[cp.Constraint]]:
        net = self.net
        br = RadialBranches.of(net)
        child, parent, r, x = br.child, br.parent, br.r, br.x
        charging, conductance = br.charging, br.conductance
        n, m = net.n_bus, child.size
        at_child, at_parent = incidence(child, n), incidence(parent, n)
        self.p_br = cp.Variable(m, name="p_branch")
        self.q_br = cp.Variable(m, name="q_branch")
        self.l_br = cp.Variable(m, name="l_branch")  # |I|² p.u.²
        v, p_br, q_br, l_br = self.v, self.p_br, self.q_br, self.l_br
        v_parent, v_child = v[parent], v[child]
        if br.tapped:
            v_parent = cp.multiply(br.parent_scale, v_parent)
            v_child = cp.multiply(br.child_scale, v_child)
        self._parent_scale = br.parent_scale
        inv_s = 1 / branch_scale(net)[child]  # the cone's per-branch scale: α = 1 / inv_s²
        l_scaled = cp.multiply(inv_s**2, l_br)  # ℓ/α
        shunt_p = cp.multiply(self.problem.gsh + conductance, v) if conductance.any() else cp.multiply(self.problem.gsh, v)
        mismatch_p = at_parent @ p_br - at_child @ (p_br - cp.multiply(r, l_br)) + shunt_p - self._p_fixed_bus()
        mismatch_q = (
            at_parent @ q_br
            - at_child @ (q_br - cp.multiply(x, l_br))
            - cp.multiply(self.problem.bsh + charging, v)
            - self.q_fixed
            - self._der_q_at_buses()
        )
        constraints = [
            v_child == v_parent - 2 * (cp.multiply(r, p_br) + cp.multiply(x, q_br)) + cp.multiply(r**2 + x**2, l_br),
            cp.SOC(
                v_parent + l_scaled,
                cp.vstack([2 * cp.multiply(inv_s, p_br), 2 * cp.multiply(inv_s, q_br), v_parent - l_scaled]),
                axis=0,
            ),
        ]
        self._parent = parent
        losses = r @ l_br + conductance @ v if conductance.any() else r @ l_br
        return mismatch_p, mismatch_q, losses, constraints

    def _cone_residual(self, value: Reader) -> np.ndarray:
        v_par = value(self.v)[:, self._parent] * self._parent_scale
        p, q, l_ = value(self.p_br), value(self.q_br), value(self.l_br)
        return np.max(v_par * l_ - p**2 - q**2, axis=1, initial=0.0)


def branch_scale(net: Network) -> np.ndarray:
    """Per bus (radial feeder), p.u. on `net.base_mva`: the apparent power its parent
    branch may carry — the larger of the nominal load |S| and the DER rating below it —
    floored at 1e-3 of the largest (1 where nothing is below any branch). The slack's
    entry is unused. The floor matters where (almost) nothing is below a branch: its
    ℓ ≈ 0, and a tiny α would magnify solver noise (more iterations per solve with a
    smaller floor; `python -m opfbench.bench opf` times the solves)."""
    load = np.abs(net.load_p_mw + 1j * net.load_q_mvar)  # each bus's own, then summed below
    der = np.zeros(net.n_bus)
    np.add.at(der, net.der_bus, net.der_rating_mw)
    for bus in net.bfs_order[::-1]:  # children before parents
        if bus != net.slack:
            load[net.parent[bus]] += load[bus]
            der[net.parent[bus]] += der[bus]
    s = np.maximum(load, der) / net.base_mva
    top = s.max(initial=0.0)
    return np.maximum(s, 1e-3 * top) if top > 0 else np.ones(net.n_bus)
