"""Clarabel for the relaxations: its settings, and re-solving a cvxpy conic problem for new
data at low overhead, with bound screening.

The OPF relaxations change only their data between snapshots — fixed injections and Q
limits, vectors θ that enter the constraints linearly. They are written in cvxpy with
those vectors as *variables* (`data_vars`) and compiled once, parameter-free, by cvxpy's
own canonicalization (public `get_problem_data`): Clarabel's form A·x + s = b, s ∈ K.
The data variables' columns are then moved into the offset: with x = [y; θ],

    A_y·y + s = b − A_θ·θ,

so each solve only updates b(θ) = b₀ + B·θ (B = −A_θ, computed for many θ at once by
`offsets`) of persistent Clarabel solvers.

Variable values are read at the columns cvxpy assigned them. cvxpy has no public API for
those columns: they are read from its compiled problem (`var_id_to_col`), which is why
pyproject.toml pins the tested cvxpy range and `tests/test_formulations_clarabel.py`
fails loudly if that internal moves (`variable_columns` raises naming it). Compiling without cvxpy
parameters matters on large feeders: cvxpy's parametrized tensor has (variables + 1)·
(parameters + 1) columns, which its SOC restructuring turns into gigabytes at 10 000
buses; the parameter-free compile is linear in the problem size.

Bound screening. Most nonnegative rows are variable bounds a·x_j ≤ b_r (a single nonzero:
v within its limits, DER Q within ±its limit), and at an optimum only a few are active. A
screened program keeps the zero, other nonnegative and SOC rows, writes a set S of bound
rows as equalities and drops the other bounds: fewer rows and barrier terms (fewer Clarabel
iterations, each cheaper; `python -m opfbench.bench opf` times it). Its solution
(x, z) answers the full program when every dropped bound holds with slack ≥ MARGIN and every bound in S
has multiplier z_r ≥ MARGIN: then x is feasible, and z with zeros on the dropped rows is
dual feasible, for the full program, so x is its optimum and the screened dual objective
(the same value at that z) is a lower bound of it (weak duality). A variable whose two
bounds coincide (a Q limit of 0) is fixed: its upper row is in S with a multiplier of any
sign. The guess for S is the last answer's S; if the check fails, one corrected guess
(violated bounds added, wrong-signed ones removed), then the full program, whose active
bounds give S (of a box narrower than MARGIN, the nearer end) for one more screened
solve; a first snapshot, without a guess, thus costs two solves. So, except at degenerate
snapshots (a bound within MARGIN of active with a multiplier below MARGIN, where the full
program answers), the answer is the screened solution at the snapshot's own active set,
whatever the guesses before it: the digits depend on the data alone, as sharing solves by
data needs.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable, Sequence

import clarabel
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

SOLVED = frozenset({"Solved", "AlmostSolved"})  # AlmostSolved: met Clarabel's reduced tolerances
INFEASIBLE = frozenset({"PrimalInfeasible", "AlmostPrimalInfeasible"})
ANSWERED = SOLVED | INFEASIBLE


TOLERANCE = 1e-8  # Clarabel gap and feasibility tolerances (the relaxations' objective in kW)
MAX_ITER = 200


def relaxation_settings() -> clarabel.DefaultSettings:
    """Clarabel's settings for the OPF relaxations (small, sparse, re-solved per snapshot)."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = MAX_ITER
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = TOLERANCE
    # Iterative refinement costs solve time for objectives within the tolerance; one thread
    # and QDLDL (deterministic, no thread pool on tiny KKT systems) are faster again
    # (`python -m opfbench.bench opf` times the result).
    settings.iterative_refinement_enable = False
    settings.max_threads = 1
    settings.direct_solve_method = "qdldl"
    # A step fraction of 0.98 instead of Clarabel's 0.99 takes fewer iterations per answer on
    # the shipped feeders' paper day (0.97: more again); `bench opf` counts them.
    settings.max_step_fraction = 0.98
    return settings


def variable_columns(data: dict) -> dict[int, int]:
    """cvxpy variable id → its first column in the compiled problem `data`
    (`get_problem_data`); cvxpy's internal, see the module docstring."""
    columns = getattr(data.get("param_prob"), "var_id_to_col", None)
    if not isinstance(columns, dict):
        raise RuntimeError(
            f"cvxpy {cp.__version__} no longer exposes the compiled problem's variable columns "
            "(param_prob.var_id_to_col), which the relaxations read; install the cvxpy range pinned "
            "in opfbench's pyproject.toml"
        )
    return columns


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


MARGIN = 1e-6  # slack of a dropped bound and multiplier of a kept one a screened answer needs
MAX_SCREENS = 8  # screened programs kept per program (least recently used dropped)


@dataclass(frozen=True)
class ConeSolve:
    """A program's answer at one offset b. status, iterations: the answering program's
    Clarabel status and iterations (after a retry on a fresh solver, "InsufficientProgress →
    Solved" and both solves' iterations): functions of the data, like x and the primal and
    dual objectives; solves: every Clarabel solve the answer took, screening guesses that
    failed their check included (depends on the guesses); screened: answered by a screened
    program (see the module docstring)."""

    status: str
    x: np.ndarray
    primal: float
    dual: float
    iterations: int
    solves: int
    screened: bool

    @property
    def final_status(self) -> str:
        """The last Clarabel status, e.g. "Solved"."""
        return self.status.split(" → ")[-1]

    @property
    def solved(self) -> bool:
        return self.final_status in SOLVED


@dataclass(frozen=True, eq=False)
class Objective:
    """A program's objective ½·xᵀ·P·x + cᵀ·x + offset: P upper triangular (Clarabel's form;
    zero for a linear objective), c, and the constant `offset` (added to the reported
    objectives)."""

    p: sp.csc_matrix
    c: np.ndarray
    offset: float


class _Clarabel:
    """One persistent Clarabel solver on rows `rows` of A·x + s = b (cones in row order)."""

    def __init__(
        self,
        objective: Objective,
        a: sp.csc_matrix,
        rows: np.ndarray,
        cones: list,
        b: np.ndarray,
        settings: clarabel.DefaultSettings,
    ):
        self.rows, self._objective, self._a, self._cones, self._settings = rows, objective, a[rows], cones, settings
        self.solver = self._fresh(b[rows])
        if not self.solver.is_data_update_allowed():
            raise ValueError("Clarabel does not allow data updates for this problem (presolve or chordal decomposition)")

    def _fresh(self, b: np.ndarray) -> clarabel.DefaultSolver:
        return clarabel.DefaultSolver(self._objective.p, self._objective.c, self._a, b, self._cones, self._settings)

    def solve(self, b: np.ndarray) -> tuple[clarabel.DefaultSolution, list[str], int]:
        """(final solution, statuses, iterations) at the full offset `b`: the solver is
        updated in place; if it ends without an answer (neither solved nor certified
        infeasible — seen as InsufficientProgress where a solver set up afresh on the same
        data succeeds), a fresh solver is built on this b, kept, and tried once more."""
        b = b[self.rows]
        self.solver.update(b=b.tolist())  # a list: Clarabel's conversion of a numpy array is slower
        solution = self.solver.solve()
        statuses, iterations = [conic_status(solution)], solution.iterations
        if statuses[0] not in ANSWERED:
            self.solver = self._fresh(b)
            solution = self.solver.solve()
            statuses.append(conic_status(solution))
            iterations += solution.iterations
        return solution, statuses, iterations


class _Screened(_Clarabel):
    """A screened program: `kept` marks the bound rows it keeps as equalities; `checked` the
    dropped bounds its answers must check (all but those whose opposite is kept: their
    slack is the box's width)."""

    def __init__(self, program: "ParametricConeProgram", rows: np.ndarray, cones: list, kept: np.ndarray, checked: np.ndarray):
        super().__init__(program.objective, program._a, rows, cones, program._b0, program._settings)
        self.kept, self.checked = kept, checked


def _vector(values: list[float]) -> np.ndarray:
    """Clarabel's solution list as an array (np.fromiter: faster than np.asarray here)."""
    return np.fromiter(values, np.float64, len(values))


def _answer(
    solution, x: np.ndarray, statuses: list[str], iterations: int, solves: int, screened: bool, offset: float
) -> ConeSolve:
    primal, dual = solution.obj_val, solution.obj_val_dual
    if offset:
        primal, dual = primal + offset, dual + offset
    return ConeSolve(" → ".join(statuses), x, primal, dual, iterations, solves, screened)


class _BoundState:
    """A program's bound rows at one offset b: right-hand sides, and which variables are
    fixed (their two bounds coincide; the upper row stands for both)."""

    def __init__(self, program: "ParametricConeProgram", b: np.ndarray):
        self.p = program
        self.rhs = b[program._bounds]
        up, lo = program._pairs  # a variable's upper and lower bound rows
        equal = self.rhs[up] / program._bound_coef[up] == self.rhs[lo] / program._bound_coef[lo]
        self.fixed = np.zeros(self.rhs.size, dtype=bool)
        self.lower_of_fixed = np.zeros(self.rhs.size, dtype=bool)
        self.any_fixed = bool(equal.any())
        if self.any_fixed:
            self.fixed[up[equal]] = True
            self.lower_of_fixed[lo[equal]] = True

    def slack(self, x: np.ndarray) -> np.ndarray:
        return self.rhs - self.p._bound_coef * x[self.p._bound_col]

    def check(self, program: _Screened, x: np.ndarray, z: Sequence[float]) -> tuple[bool, tuple]:
        """(does the screened `program`'s solution (x, z) answer the full program, the
        corrected guess)."""
        kept = program.kept
        n_zero, n_kept = self.p._n_zero, len(z) - self.p._n_rest - self.p._n_zero
        slack = self.slack(x)
        mult = np.asarray(z[n_zero : n_zero + n_kept])
        signs_ok = (mult[~self.fixed[kept]] if self.any_fixed else mult) >= MARGIN
        if (slack[program.checked] >= MARGIN).all() and signs_ok.all():
            return True, ()
        signed = np.zeros(kept.size)
        signed[kept] = mult
        corrected = ((kept & (signed >= 0.0)) | (~kept & (slack < 0.0)) | self.fixed) & ~self.lower_of_fixed
        return False, tuple(np.flatnonzero(corrected).tolist())

    def active(self, x: np.ndarray) -> tuple:
        """The bounds active at the full program's solution x: slack below MARGIN, a fixed
        variable by its upper row; of a box narrower than MARGIN, the nearer end only."""
        slack = self.slack(x)
        active = ((slack < MARGIN) | self.fixed) & ~self.lower_of_fixed
        up, lo = self.p._pairs
        both = active[up] & active[lo]
        if both.any():
            active[np.where(slack[up] <= slack[lo], lo, up)[both]] = False
        return tuple(np.flatnonzero(active).tolist())


def _objective(problem: cp.Problem, data: dict, is_data: np.ndarray) -> Objective:
    """The compiled objective without the data columns: ValueError where a data variable
    enters it, linearly or in the quadratic term (a solve would then depend on θ in a way
    the offsets do not carry)."""
    c = np.asarray(data["c"], dtype=float)
    raw = data.get("P")
    p = sp.csc_matrix(raw) if raw is not None else sp.csc_matrix((c.size, c.size))
    p.eliminate_zeros()
    rows, cols = p.nonzero()
    if np.any(c[is_data] != 0) or np.any(is_data[rows]) or np.any(is_data[cols]):
        raise ValueError("the data variables must not enter the objective")
    keep = ~is_data
    # The objective's constant term: its value at x = 0 (cvxpy keeps it out of P and c).
    held = {v: v.value for v in problem.variables()}
    try:
        for v in held:
            v.value = np.zeros(v.shape)
        offset = float(problem.objective.value)
    finally:
        for v, value in held.items():
            v.value = value
    return Objective(sp.triu(p[keep][:, keep]).tocsc(), c[keep], offset)


class ParametricConeProgram:
    """A cvxpy problem (a linear or convex quadratic objective — cvxpy's P matrix is handed
    to Clarabel, and a constant term added to the reported objectives; zero, nonnegative
    and SOC constraints) whose vector variables `data_vars` are data θ, fixed per solve
    (they must not enter the objective), solved by persistent Clarabel instances with bound
    screening (the screening check is the KKT conditions, which hold for a quadratic
    objective as for a linear one)."""

    def __init__(
        self, problem: cp.Problem, data_vars: Sequence[cp.Variable], settings: clarabel.DefaultSettings, screening: bool = True
    ):
        self.screening = screening
        if problem.parameters():
            raise ValueError("write the data as variables (data_vars), not cvxpy parameters")
        data, _, _ = problem.get_problem_data(cp.CLARABEL)
        if data.get("lower_bounds") is not None or data.get("upper_bounds") is not None:
            raise ValueError("variable bounds attributes are not supported; write them as constraints")
        var_col = variable_columns(data)
        a, c = data["A"].tocsc(), np.asarray(data["c"], dtype=float)
        data_cols = [
            np.arange(var_col[v.id], var_col[v.id] + v.size) if v.id in var_col else np.full(v.size, -1) for v in data_vars
        ]
        self._sizes = [v.size for v in data_vars]
        is_data = np.zeros(c.size, dtype=bool)
        theta_cols = np.concatenate(data_cols) if data_cols else np.zeros(0, dtype=int)
        is_data[theta_cols[theta_cols >= 0]] = True
        objective = _objective(problem, data, is_data)
        # B = −A_θ = −A·S with S selecting the data columns (a data entry that appears
        # nowhere has a zero column).
        present = np.flatnonzero(theta_cols >= 0)
        select = sp.csc_matrix((np.ones(present.size), (theta_cols[present], present)), shape=(c.size, theta_cols.size))
        self._b_theta = (-(a @ select)).tocsc()
        self._b0 = np.asarray(data["b"], dtype=float)
        self._a, self.objective = a[:, ~is_data], objective
        new_col = np.cumsum(~is_data) - 1
        self._var_col = {vid: int(new_col[col]) for vid, col in var_col.items() if not is_data[col]}
        self._settings, self._dims = settings, data["dims"]
        self._screening(self._dims)
        self.full = _Clarabel(objective, self._a, np.arange(self._b0.size), _cones(data["dims"]), self._b0, settings)
        self._screens: OrderedDict[tuple, _Screened] = OrderedDict()
        self._guess: tuple | None = None

    def _screening(self, dims) -> None:
        """The bound rows (nonnegative rows with one nonzero), their variable and coefficient,
        each one's opposite bound on the same variable (or −1), and the rows every screened
        program keeps."""
        self._n_zero = dims.zero
        nonneg = np.arange(dims.zero, dims.zero + dims.nonneg)
        rows = sp.csr_matrix(self._a[nonneg])
        single = np.diff(rows.indptr) == 1
        self._bounds = nonneg[single]
        self._bound_col = rows.indices[rows.indptr[:-1][single]]
        self._bound_coef = rows.data[rows.indptr[:-1][single]]
        upper = self._bound_coef > 0
        row_of = np.full((2, self.n_x), -1)  # [upper, lower] bound row of each variable
        row_of[0, self._bound_col[upper]] = np.flatnonzero(upper)
        row_of[1, self._bound_col[~upper]] = np.flatnonzero(~upper)
        self._opposite = np.where(upper, row_of[1, self._bound_col], row_of[0, self._bound_col])
        up = np.flatnonzero((self._opposite >= 0) & (self._bound_coef > 0))
        self._pairs = (up, self._opposite[up])
        self._other_nonneg = nonneg[~single]
        self._soc_rows = np.arange(dims.zero + dims.nonneg, self._b0.size)
        self._n_rest = self._other_nonneg.size + self._soc_rows.size  # rows after the kept bounds
        self._soc_cones = [clarabel.SecondOrderConeT(d) for d in dims.soc]

    @property
    def n_x(self) -> int:
        """Length of the solution vector x."""
        return self.objective.c.size

    @property
    def full_a(self) -> sp.csc_matrix:
        """The full program's A (the data columns moved into b): its rows are the cones' in order."""
        return self._a

    @property
    def cone_dims(self):
        """cvxpy's cone dimensions of the full program (zero, nonneg, soc)."""
        return self._dims

    def offsets(self, thetas: np.ndarray) -> np.ndarray:
        """The constraint offsets b(θ) = b₀ + B·θ, one row per row of `thetas` (S, n_θ): the
        data variables' values concatenated in order."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        if thetas.shape[1] != sum(self._sizes):
            raise ValueError(f"θ has {thetas.shape[1]} entries, the data variables {sum(self._sizes)}")
        return self._b0 + (self._b_theta @ thetas.T).T

    def _screen(self, active: tuple) -> _Screened:
        """The screened program with the bounds `active` (indices into the bound rows) as
        equalities and the other bounds dropped, built once (least recently used dropped);
        its `kept` marks the bounds in `active`."""
        program = self._screens.get(active)
        if program is None:
            rows = np.concatenate([np.arange(self._n_zero), self._bounds[list(active)], self._other_nonneg, self._soc_rows])
            cones = [clarabel.ZeroConeT(self._n_zero + len(active))]
            cones += [clarabel.NonnegativeConeT(self._other_nonneg.size)] if self._other_nonneg.size else []
            kept = np.zeros(self._bounds.size, dtype=bool)
            kept[list(active)] = True
            checked = ~kept & ~((self._opposite >= 0) & kept[self._opposite])
            program = self._screens[active] = _Screened(self, rows, cones + self._soc_cones, kept, checked)
            while len(self._screens) > MAX_SCREENS:
                self._screens.popitem(last=False)
        self._screens.move_to_end(active)
        return program

    def solve(self, b: np.ndarray) -> ConeSolve:
        """Solve at the constraint offset `b` (a row of `offsets`), screened where the check
        allows (module docstring)."""
        if not (self.screening and self._bounds.size):
            solution, statuses, iterations = self.full.solve(b)
            return _answer(solution, _vector(solution.x), statuses, iterations, 1, False, self.objective.offset)
        bounds = _BoundState(self, b)
        solves = 0
        tried = set()
        guess = self._guess
        for _ in range(2):  # the last answer's S, then one corrected guess
            if guess is None or guess in tried:
                break
            tried.add(guess)
            program = self._screen(guess)
            solution, statuses, iterations = program.solve(b)
            solves += 1
            if statuses[-1] not in SOLVED:
                break
            x = _vector(solution.x)
            ok, corrected = bounds.check(program, x, solution.z)
            if ok:
                self._guess = guess
                return _answer(solution, x, statuses, iterations, solves, True, self.objective.offset)
            guess = corrected
        solution, statuses, iterations = self.full.solve(b)
        solves += 1
        x = _vector(solution.x)
        if statuses[-1] not in SOLVED:
            return _answer(solution, x, statuses, iterations, solves, False, self.objective.offset)
        self._guess = active = bounds.active(x)
        if active not in tried:
            program = self._screen(active)
            screened, screened_statuses, screened_iterations = program.solve(b)
            solves += 1
            if screened_statuses[-1] in SOLVED:
                screened_x = _vector(screened.x)
                if bounds.check(program, screened_x, screened.z)[0]:
                    return _answer(
                        screened, screened_x, screened_statuses, screened_iterations, solves, True, self.objective.offset
                    )
        return _answer(solution, x, statuses, iterations, solves, False, self.objective.offset)

    def reader(self, x: np.ndarray) -> Callable[[cp.Variable], np.ndarray]:
        """A function reading a (vector, non-data) variable's value from solution vectors
        `x` (n_x,) or stacked (S, n_x): the last axis holds the variable's entries."""
        x = np.asarray(x)

        def value(var: cp.Variable) -> np.ndarray:
            if var.size == 0:  # e.g. the DER setpoints of a case without DER
                return x[..., :0]
            start = self._var_col[var.id]
            return x[..., start : start + var.size]

        return value
