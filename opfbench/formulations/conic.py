"""Re-solving a parametrized cvxpy problem with Clarabel at low overhead.

cvxpy's DPP caching skips recompilation, but each `problem.solve()` still re-applies the
parameters to the whole canonical program, rebuilds the Clarabel data and unpacks every
variable: on the 33-bus SOCP that is ≈ 4 ms of overhead around a ≈ 1.5 ms solve. When
the parameters enter the constraint offsets only (A and c fixed — true of the OPF
relaxations, whose parameters are loads and limits), the canonical offset is affine,
b(θ) = b₀ + B·θ. We read b₀ and B once from cvxpy's own canonicalization (public
`get_problem_data`, evaluated at θ = 0 and at two probes — `_offset_map_one_per_row` —
or, if that does not reproduce b at a random θ, at each unit vector), build one Clarabel
solver, and each re-solve only updates b. Variable values are read at the columns cvxpy
assigned them. The model is still cvxpy's; only the per-solve plumbing is bypassed.
"""

from __future__ import annotations

from typing import Sequence

import clarabel
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

AFFINE_CHECK_RTOL = 1e-9
SOLVED = frozenset({"Solved", "AlmostSolved"})  # AlmostSolved: met Clarabel's reduced tolerances
INFEASIBLE = frozenset({"PrimalInfeasible", "AlmostPrimalInfeasible"})
ANSWERED = SOLVED | INFEASIBLE


def conic_status(solution: clarabel.DefaultSolution) -> str:
    """Clarabel's status name, e.g. "Solved"."""
    return str(solution.status).split(".")[-1]


def _cones(dims) -> list:
    """Clarabel cones for cvxpy's cone dimensions (zero, nonnegative and second-order only)."""
    if dims.exp or dims.psd or dims.p3d or getattr(dims, "pnd", []):
        raise ValueError("only zero, nonnegative and second-order cones are supported")
    cones: list = []
    if dims.zero:
        cones.append(clarabel.ZeroConeT(dims.zero))
    if dims.nonneg:
        cones.append(clarabel.NonnegativeConeT(dims.nonneg))
    cones += [clarabel.SecondOrderConeT(d) for d in dims.soc]
    return cones


class ParametricConeProgram:
    """A DPP cvxpy problem (linear objective, SOC constraints) over 1-D parameters that
    appear only in constraint offsets, solved by one persistent Clarabel instance."""

    def __init__(self, problem: cp.Problem, params: Sequence[cp.Parameter], settings: clarabel.DefaultSettings):
        if not problem.is_dpp():
            raise ValueError("the problem is not DPP: its parameters cannot be updated without recompiling")
        if any(p.ndim != 1 for p in params):
            raise ValueError("parameters must be vectors")
        self.problem = problem
        self.params = tuple(params)
        self._sizes = [p.size for p in self.params]
        n_theta = sum(self._sizes)
        data0 = self._data(np.zeros(n_theta))
        if data0.get("lower_bounds") is not None or data0.get("upper_bounds") is not None:
            raise ValueError("variable bounds attributes are not supported; write them as constraints")
        self._a, self._c, self._b0 = data0["A"].tocsc(), np.asarray(data0["c"]), np.asarray(data0["b"])
        check = np.random.default_rng(0).uniform(0.1, 1.0, n_theta)
        self._b_theta = self._offset_map_one_per_row(n_theta)
        if not self._affine(check):
            self._b_theta = self._offset_map_by_columns(n_theta)
            if not self._affine(check):
                raise ValueError("the parameters do not enter the constraint offsets affinely only")
        self._var_col = data0["param_prob"].var_id_to_col
        self._cones, self._settings = _cones(data0["dims"]), settings
        self.solver = self._fresh_solver(self._b0)
        if not self.solver.is_data_update_allowed():
            raise ValueError("Clarabel does not allow data updates for this problem (presolve or chordal decomposition)")

    def _fresh_solver(self, b: np.ndarray) -> clarabel.DefaultSolver:
        n_x = self._c.size
        return clarabel.DefaultSolver(sp.csc_matrix((n_x, n_x)), self._c, self._a, b, self._cones, self._settings)

    def _data(self, theta: np.ndarray) -> dict:
        for p, chunk in zip(self.params, np.split(theta, np.cumsum(self._sizes)[:-1]), strict=True):
            p.value = chunk
        data, _, _ = self.problem.get_problem_data(cp.CLARABEL)
        return data

    def _offset_map_one_per_row(self, n_theta: int) -> sp.csc_matrix:
        """B from two evaluations, assuming each offset row depends on at most one
        parameter entry (true of loads and limits): at θ_j = j + 1 and θ_j = (j + 1)²
        a row's changes d₁ = B_rj·(j + 1) and d₂ = B_rj·(j + 1)² name j = d₂/d₁ − 1.
        The caller verifies the result at a random θ."""
        a = np.arange(1.0, n_theta + 1.0)
        d1, d2 = self._data(a)["b"] - self._b0, self._data(a**2)["b"] - self._b0
        rows = np.flatnonzero(d1)
        cols = np.rint(d2[rows] / d1[rows]).astype(np.int64) - 1
        good = (cols >= 0) & (cols < n_theta)
        rows, cols = rows[good], cols[good]
        return sp.csc_matrix((d1[rows] / (cols + 1.0), (rows, cols)), shape=(self._b0.size, n_theta))

    def _offset_map_by_columns(self, n_theta: int) -> sp.csc_matrix:
        """B column by column (one evaluation per parameter entry): any affine offset."""
        cols = [sp.csc_matrix((self._data(np.eye(1, n_theta, j).ravel())["b"] - self._b0)[:, None])
                for j in range(n_theta)]
        return sp.hstack(cols, format="csc") if cols else sp.csc_matrix((self._b0.size, 0))

    def _affine(self, theta: np.ndarray) -> bool:
        """A and c do not depend on θ and b(θ) = b₀ + B·θ at `theta`."""
        data = self._data(theta)
        same_a = (data["A"].tocsc() != self._a).nnz == 0
        same_c = np.array_equal(np.asarray(data["c"]), self._c)
        b = self.offset(theta)
        return bool(same_a and same_c and np.allclose(data["b"], b, rtol=AFFINE_CHECK_RTOL, atol=AFFINE_CHECK_RTOL))

    def offset(self, theta: np.ndarray) -> np.ndarray:
        """The canonical constraint offset b(θ) = b₀ + B·θ."""
        return self._b0 + self._b_theta @ theta

    def solve(self, theta: np.ndarray) -> list[clarabel.DefaultSolution]:
        """Solve at parameter vector θ (the parameters' values concatenated in order).

        Returns the solutions of every attempt, the last one final: the persistent solver
        is updated in place; if it ends without an answer (neither solved nor certified
        infeasible — seen as InsufficientProgress where a solver set up afresh on the
        same data succeeds), a fresh solver is built on this b, kept for the next
        updates, and tried once more."""
        b = self.offset(np.asarray(theta, dtype=float))
        self.solver.update(b=b)
        attempts = [self.solver.solve()]
        if conic_status(attempts[0]) not in ANSWERED:
            self.solver = self._fresh_solver(b)
            attempts.append(self.solver.solve())
        return attempts

    def value(self, solution: clarabel.DefaultSolution, var: cp.Variable) -> np.ndarray:
        """A (vector) variable's value in a solution."""
        if var.size == 0:  # e.g. the DER setpoints of a case without DER
            return np.zeros(0)
        start = self._var_col[var.id]
        return np.asarray(solution.x[start:start + var.size])
