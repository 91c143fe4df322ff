"""Re-solving a cvxpy conic problem with Clarabel for new data at low overhead.

The OPF relaxations change only their data between snapshots — fixed injections and Q
limits, vectors θ that enter the constraints linearly. They are written in cvxpy with
those vectors as *variables* (`data_vars`) and compiled once, parameter-free, by cvxpy's
own canonicalization (public `get_problem_data`): Clarabel's form A·x + s = b, s ∈ K.
The data variables' columns are then moved into the offset: with x = [y; θ],

    A_y·y + s = b − A_θ·θ,

so each solve only updates b(θ) = b₀ + B·θ (B = −A_θ, computed for many θ at once by
`offsets`) of one persistent Clarabel solver.
Variable values are read at the columns cvxpy assigned them. Compiling without cvxpy
parameters matters on large feeders: cvxpy's parametrized tensor has (variables + 1)·
(parameters + 1) columns, which its SOC restructuring turns into gigabytes at 10 000
buses; the parameter-free compile is linear in the problem size.
"""

from __future__ import annotations

from typing import Callable, Sequence

import clarabel
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

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
    """A cvxpy problem (linear objective; zero, nonnegative and SOC constraints) whose
    vector variables `data_vars` are data θ, fixed per solve (they must not enter the
    objective), solved by one persistent Clarabel instance."""

    def __init__(self, problem: cp.Problem, data_vars: Sequence[cp.Variable], settings: clarabel.DefaultSettings):
        if problem.parameters():
            raise ValueError("write the data as variables (data_vars), not cvxpy parameters")
        data, _, _ = problem.get_problem_data(cp.CLARABEL)
        if data.get("lower_bounds") is not None or data.get("upper_bounds") is not None:
            raise ValueError("variable bounds attributes are not supported; write them as constraints")
        var_col = data["param_prob"].var_id_to_col
        a, c = data["A"].tocsc(), np.asarray(data["c"], dtype=float)
        data_cols = [np.arange(var_col[v.id], var_col[v.id] + v.size) if v.id in var_col
                     else np.full(v.size, -1) for v in data_vars]
        self._sizes = [v.size for v in data_vars]
        is_data = np.zeros(c.size, dtype=bool)
        theta_cols = np.concatenate(data_cols) if data_cols else np.zeros(0, dtype=int)
        is_data[theta_cols[theta_cols >= 0]] = True
        if np.any(c[is_data] != 0):
            raise ValueError("the data variables must not enter the objective")
        # B = −A_θ = −A·S with S selecting the data columns (a data entry that appears
        # nowhere has a zero column).
        present = np.flatnonzero(theta_cols >= 0)
        select = sp.csc_matrix((np.ones(present.size), (theta_cols[present], present)), shape=(c.size, theta_cols.size))
        self._b_theta = (-(a @ select)).tocsc()
        self._b0 = np.asarray(data["b"], dtype=float)
        self._a, self._c = a[:, ~is_data], c[~is_data]
        new_col = np.cumsum(~is_data) - 1
        self._var_col = {vid: int(new_col[col]) for vid, col in var_col.items() if not is_data[col]}
        self._cones, self._settings = _cones(data["dims"]), settings
        self.solver = self._fresh_solver(self._b0)
        if not self.solver.is_data_update_allowed():
            raise ValueError("Clarabel does not allow data updates for this problem (presolve or chordal decomposition)")

    @property
    def n_x(self) -> int:
        """Length of the solution vector x."""
        return self._c.size

    def _fresh_solver(self, b: np.ndarray) -> clarabel.DefaultSolver:
        n_x = self._c.size
        return clarabel.DefaultSolver(sp.csc_matrix((n_x, n_x)), self._c, self._a, b, self._cones, self._settings)

    def offsets(self, thetas: np.ndarray) -> np.ndarray:
        """The constraint offsets b(θ) = b₀ + B·θ, one row per row of `thetas` (S, n_θ): the
        data variables' values concatenated in order."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        if thetas.shape[1] != sum(self._sizes):
            raise ValueError(f"θ has {thetas.shape[1]} entries, the data variables {sum(self._sizes)}")
        return self._b0 + (self._b_theta @ thetas.T).T

    def solve(self, b: np.ndarray) -> list[clarabel.DefaultSolution]:
        """Solve at the constraint offset `b` (a row of `offsets`).

        Returns the solutions of every attempt, the last one final: the persistent solver
        is updated in place; if it ends without an answer (neither solved nor certified
        infeasible — seen as InsufficientProgress where a solver set up afresh on the
        same data succeeds), a fresh solver is built on this b, kept for the next
        updates, and tried once more."""
        self.solver.update(b=b)
        attempts = [self.solver.solve()]
        if conic_status(attempts[0]) not in ANSWERED:
            self.solver = self._fresh_solver(b)
            attempts.append(self.solver.solve())
        return attempts

    def reader(self, x: np.ndarray) -> Callable[[cp.Variable], np.ndarray]:
        """A function reading a (vector, non-data) variable's value from solution vectors
        `x` (n_x,) or stacked (S, n_x): the last axis holds the variable's entries."""
        x = np.asarray(x)

        def value(var: cp.Variable) -> np.ndarray:
            if var.size == 0:  # e.g. the DER setpoints of a case without DER
                return x[..., :0]
            start = self._var_col[var.id]
            return x[..., start:start + var.size]

        return value
