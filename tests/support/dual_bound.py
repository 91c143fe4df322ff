"""A rigorous lower bound on a DistFlow relaxation's optimum from any dual vector z of its
conic program (`clarabel_adapter.ParametricConeProgram`, linear objective): weak duality
with the dual residual accounted for, so the bound does not rest on the solver's
tolerances.

The program is min cᵀx s.t. A·x + s = b, s ∈ K (zero, nonnegative, SOC cones; K self-dual
but for the zero cone's free multipliers). With z projected into K* and r = Aᵀz + c, every
feasible x has cᵀx = rᵀx − bᵀz + zᵀs ≥ rᵀx − bᵀz. At the minimiser x* (objective f*):
- v and q lie in the box of the program's own bound rows (vmin² ≤ v ≤ vmax², |q| ≤ q_limit,
  v_slack fixed): their terms are at least Σ min(r_j·lo_j, r_j·hi_j);
- every cost coefficient is ≥ 0 on nonnegative columns (the branch currents ℓ ≥ 0 by their
  cone, r·ℓ and g·v losses), so Σ c_ℓ·ℓ* ≤ f*: r_ℓ·ℓ* ≥ −α·f*, α = max(0, max_j −r_j/c_j);
- the branch flows by their cone: P² + Q² ≤ v_parent·ℓ ≤ vmax²·f*/c_ℓ, so
  |r_P·P*| + |r_Q·Q*| ≤ β·√f*.
So f* ≥ B₀ − α·f* − β·√f*, a quadratic in √f* solved for the bound. Floating-point
rounding of the final sums (≈ 1e-16 relative) is not accounted for."""

from __future__ import annotations

import numpy as np

from opfbench.formulations.models.distflow import DistFlowSocp, RadialBranches


def _into_dual_cone(z: np.ndarray, dims) -> np.ndarray:
    """z projected into K*: nonnegative rows clipped at 0, each SOC block onto the cone."""
    z = z.copy()
    nz, nn = dims.zero, dims.nonneg
    z[nz : nz + nn] = np.maximum(z[nz : nz + nn], 0.0)
    i = nz + nn
    for d in dims.soc:
        t, u = z[i], z[i + 1 : i + d]
        norm = np.linalg.norm(u)
        if norm > t:
            a = max((t + norm) / 2, 0.0)
            z[i], z[i + 1 : i + d] = a, a * u / norm
        i += d
    return z


def rigorous_bound_kw(relax: DistFlowSocp, theta: np.ndarray, z: np.ndarray) -> float:
    """A lower bound (kW) on the optimum of `relax` (a DistFlow relaxation without
    curtailment) at data θ (`conic.data_vector`, one snapshot), from the full program's
    dual vector `z` (module docstring)."""
    program, problem, net = relax.program, relax.problem, relax.net
    assert program.objective.p.nnz == 0 and program.objective.offset == 0.0 and relax.curtail is None
    b = program.offsets(theta[None])[0]
    z = _into_dual_cone(np.asarray(z, dtype=float), program.cone_dims)
    c = program.objective.c
    r = program.full_a.T @ z + c
    columns = program.reader(np.arange(program.n_x))
    v, q, p_br, q_br, l_br = (columns(var) for var in (relax.v, relax.q, relax.p_br, relax.q_br, relax.l_br))
    assert np.array_equal(np.sort(np.concatenate([v, q, p_br, q_br, l_br])), np.arange(program.n_x))
    assert np.all(c[v] >= 0) and np.all(c[l_br] > 0) and not np.any(c[q]) and not np.any(c[p_br]) and not np.any(c[q_br])
    v_lo, v_hi = np.full(net.n_bus, problem.v_slack**2), np.full(net.n_bus, problem.v_slack**2)
    v_lo[problem.others], v_hi[problem.others] = problem.vm_min**2, problem.vm_max**2
    q_hi = theta[2 * net.n_bus :]
    b0 = -float(b @ z)
    b0 += float(np.minimum(r[v] * v_lo, r[v] * v_hi).sum() + np.minimum(r[q] * -q_hi, r[q] * q_hi).sum())
    alpha = max(0.0, float(np.max(-r[l_br] / c[l_br])))
    branches = RadialBranches.of(net)
    v_parent = v_hi[branches.parent] * branches.parent_scale
    beta = float(((np.abs(r[p_br]) + np.abs(r[q_br])) * np.sqrt(v_parent / c[l_br])).sum())
    if b0 <= 0:
        return b0
    root = (-beta + np.sqrt(beta**2 + 4 * (1 + alpha) * b0)) / (2 * (1 + alpha))
    return float(root * root)
