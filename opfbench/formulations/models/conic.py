"""What every conic model of the OPF problem shares (cvxpy + Clarabel): the relaxations
(`distflow`, `jabr`) and the approximations (`lindistflow`).

The OPF problem of `problem.OpfProblem` (as the AC OPF solves it), in v = |V|²: DER Q
within ±(1 − k)·Qmax(P), v_slack², vmin² ≤ v ≤ vmax², the power balance and slack rule
of `OpfProblem.balance`; objective = the model's branch losses (linear, or convex
quadratic). A model writes how the voltages couple the branch flows: its own variables,
the bus mismatches, its objective and its constraints (`ConicModel._network_model`). For
a relaxation, any AC-feasible point maps to a feasible point with the same losses, so its
optimum is a lower bound on the AC OPF's; an approximation's optimum is an estimate.

With `curtail` (a `problem.PqCapability`) the DER's active power is a variable too, within
[min(P, 0), P] of the power P it has, Q within the capability at the power delivered
(linear pieces and an S̄ cone), and the objective the losses plus the power curtailed
(written as losses − ΣP_DER, the data ΣP added to the optimum).

The objective reported is min(primal, dual) objective of Clarabel's solution (kW): not a
proof by itself (Clarabel checks its tolerances on its equilibrated program), so
`tests/test_relaxation_bound.py` holds it against a rigorous dual bound (weak duality with
the dual residual accounted for) where the screened and full programs disagree. Clarabel's
"AlmostSolved" (reduced tolerances met) counts as solved and is recorded as such in
solver_status; a solve that stalls after an in-place data update is retried once on a
fresh solver (`clarabel_adapter.ParametricConeProgram.solve`), recorded as e.g.
"InsufficientProgress → Solved".

A relaxation's `relaxation_gap` = max over branches of its cone residual at the optimum,
in p.u.² (`_cone_residual`): 0 (in practice ≲ 1e-7, the solver's tolerance) means the
relaxation is exact on every branch; the AC losses of the setpoints against the bound is
the end-to-end measure. A model without cones has none (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cvxpy as cp
import numpy as np

from opfbench.formulations.problem import OpfProblem, PqCapability, Row
from opfbench.formulations.solvers.clarabel_adapter import INFEASIBLE as CONIC_INFEASIBLE
from opfbench.formulations.solvers.clarabel_adapter import ParametricConeProgram, relaxation_settings
from opfbench.network import Network
from opfbench.timing import elapsed_ms, now

NOT_SOLVED = "not solved"  # a SnapshotSolve's outcome where the caller skipped the snapshot
Reader = Callable[[cp.Variable], np.ndarray]  # a variable's values in stacked solutions, (S, size)


@dataclass(frozen=True)
class SnapshotSolve:
    """One snapshot's solve of a model that solves snapshots independently. outcome:
    "optimal" | "infeasible" (certified by the solver) | "failed" | "not solved"
    (`not_solved`: a caller had no use for it); solver_status: the solver's own status;
    objective_kw: the model's optimum (kW; a relaxation's is a lower bound on the AC
    OPF's); solve_ms: wall time of the data updates and solves; iterations: the answering
    solve's; solves: every solve the answer took (`clarabel_adapter.ConeSolve`);
    slack_p_pu: the slack bus's active injection at the optimum (p.u., positive = import
    from the upstream grid). Where not optimal, objective_kw, relaxation_gap and slack_p_pu
    are NaN and q_pu is None."""

    outcome: str
    solver_status: str
    objective_kw: float
    q_pu: np.ndarray | None
    relaxation_gap: float
    solve_ms: float
    iterations: int
    solves: int
    slack_p_pu: float = np.nan
    p_pu: np.ndarray | None = None  # the DER's active power, where the model curtails

    @classmethod
    def not_solved(cls) -> "SnapshotSolve":
        """The record of a snapshot left unsolved (no status, no time, NaN figures)."""
        return cls(NOT_SOLVED, "", np.nan, None, np.nan, 0.0, 0, 0)

    @property
    def optimal(self) -> bool:
        return self.outcome == "optimal"

    @property
    def infeasible(self) -> bool:
        return self.outcome == "infeasible"

    def diagnostics(self) -> dict:
        """What the solve contributes to a result's per-snapshot `extra`."""
        return {
            "solve_ms": self.solve_ms,
            "iterations": int(self.iterations),
            "solves": int(self.solves),
            "solver_status": self.solver_status,
        }


def data_vector(s_fixed: np.ndarray, q_limit: np.ndarray) -> np.ndarray:
    """A snapshot's data θ = [Re s_fixed, Im s_fixed, q_limit] (p.u.); `s_fixed`/`q_limit`
    may be one snapshot or (S, ·) arrays."""
    return np.concatenate([s_fixed.real, s_fixed.imag, q_limit], axis=-1)


def curtail_vector(s_fixed: np.ndarray, p_avail: np.ndarray, p_low: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """A snapshot's data θ where the model curtails = [Re s_fixed, Im s_fixed, P, min(P, 0),
    offsets of piece 0, of piece 1] (p.u.; `problem.CurtailData`'s arrays, (S, ·))."""
    return np.concatenate([s_fixed.real, s_fixed.imag, p_avail, p_low, offset[..., 0], offset[..., 1]], axis=-1)


def _rows(row: Row) -> list[cp.Constraint]:
    """A problem row lo ≤ expr ≤ hi as cvxpy constraints."""
    if np.array_equal(row.lo, row.hi):
        return [row.expr == row.lo]
    return ([row.expr >= row.lo] if np.all(np.isfinite(row.lo)) else []) + (
        [row.expr <= row.hi] if np.all(np.isfinite(row.hi)) else []
    )


def screens(net: Network) -> bool:
    """Whether the relaxation of `net` uses bound screening (`solvers.clarabel_adapter`):
    not on feeders with a DER at every other bus or more (SimBench's MV grids). There the
    active set moves with almost every 15-min step and is often degenerate: the last
    step's guess mostly fails its check and a step costs several Clarabel solves where one
    full solve answers (`python -m opfbench.bench opf`'s `mv_*` keys time them)."""
    return len(net.ders) < net.n_bus / 2


class ConicModel:
    """A conic model of one `OpfProblem`, built once; `solve` per snapshot.

    Data (cvxpy variables that `ParametricConeProgram` holds fixed per solve): p_fixed,
    q_fixed (n_bus,) fixed injections and q_limit (n_der,) usable Q limit, all p.u.
    A model subclasses it with its `_network_model`; a relaxation with its `_cone_residual`;
    a model whose objective is not the losses its balance carries with `_slack_p_pu`.
    """

    def __init__(self, net: Network, slack_export: bool = True, curtail: PqCapability | None = None):
        self.problem = problem = OpfProblem.of(net, slack_export)
        self.net, self.curtail = net, curtail
        n, n_der = net.n_bus, len(net.ders)
        self.p_fixed = cp.Variable(n, name="p_fixed")
        self.q_fixed = cp.Variable(n, name="q_fixed")
        self.q = cp.Variable(n_der, name="q_der")
        self.p = cp.Variable(n_der, name="p_der") if curtail is not None else None
        self.v = cp.Variable(n, name="v")  # |V|² p.u.²
        mismatch_p, mismatch_q, losses, constraints = self._network_model()
        others = problem.others
        for row in problem.balance(mismatch_p, mismatch_q, lambda e, i: e[i]):
            constraints += _rows(row)
        constraints += [
            self.v[problem.slack] == problem.v_slack**2,
            self.v[others] >= problem.vm_min**2,
            self.v[others] <= problem.vm_max**2,
        ]
        objective = losses
        if curtail is None:
            self.q_limit = cp.Variable(n_der, name="q_limit")
            constraints += [self.q <= self.q_limit, self.q >= -self.q_limit]
            data_vars: tuple[cp.Variable, ...] = (self.p_fixed, self.q_fixed, self.q_limit)
        else:
            assert self.p is not None
            constraints += self._capability(curtail)
            objective = losses - cp.sum(self.p)
            data_vars = (self.p_fixed, self.q_fixed, self.p_avail, self.p_low, *self.offset)
        self.cvxpy_problem = cp.Problem(cp.Minimize(problem.kw_per_pu * objective), constraints)
        self.program = ParametricConeProgram(self.cvxpy_problem, data_vars, relaxation_settings(), screening=screens(net))

    def _capability(self, cap: PqCapability) -> list[cp.Constraint]:
        """The DER's active power within [min(P, 0), P] and Q within the capability at it
        (`PqCapability`; the data P, min(P, 0) and the offsets as variables held fixed)."""
        assert self.p is not None
        n_der = len(self.net.ders)
        self.p_avail = cp.Variable(n_der, name="p_avail")
        self.p_low = cp.Variable(n_der, name="p_low")
        self.offset = (cp.Variable(n_der, name="offset_0"), cp.Variable(n_der, name="offset_1"))
        out = [self.p <= self.p_avail, self.p >= self.p_low]
        for j, offset in enumerate(self.offset):
            reach = cp.multiply(cap.slope[:, j], self.p) + offset
            out += [self.q <= reach, -self.q <= reach]
        c = np.flatnonzero(cap.circle)
        if c.size:
            out.append(cp.SOC(cap.share * cap.s_pu[c], cp.vstack([self.q[c], cap.share * self.p[c]]), axis=0))
        return out

    def _p_fixed_bus(self) -> cp.Expression:
        """The active power injected at every bus that the model's flows balance: the fixed
        injections and, where the model curtails, the DER's active power."""
        return self.p_fixed if self.p is None else self.p_fixed + self.problem.der_at_bus @ self.p

    def _network_model(self) -> tuple[cp.Expression, cp.Expression, cp.Expression, list[cp.Constraint]]:
        """(mismatch_p, mismatch_q, branch losses, model constraints), p.u., per `problem`."""
        raise NotImplementedError

    def _cone_residual(self, value: Reader) -> np.ndarray | None:
        """Largest cone residual (p.u.²) of each of stacked solutions; `value(var)` reads a
        variable as (S, size). None: the model has no cones."""
        return None

    def _slack_p_pu(self, value: Reader, thetas: np.ndarray, objective_kw: np.ndarray) -> np.ndarray:
        """The slack's active injection (p.u.) at each of stacked optima: summed over all
        buses the mismatches are the branch losses plus the shunts' P minus the fixed
        injections; every non-slack mismatch is 0, so where the objective is the branch
        losses the balance carries, this is the slack's P."""
        n = self.net.n_bus
        return objective_kw / self.problem.kw_per_pu + value(self.v) @ self.problem.gsh - thetas[:, :n].sum(axis=1)

    def _der_q_at_buses(self) -> cp.Expression:
        return self.problem.der_at_bus @ self.q

    def solve(self, s_fixed: np.ndarray, q_limit: np.ndarray) -> SnapshotSolve:
        """Solve one snapshot: fixed injections `s_fixed` (n_bus,) complex p.u., usable
        Q limits `q_limit` (n_der,) p.u."""
        return self.solve_data(data_vector(s_fixed, q_limit)[None])[0]

    def solve_data(self, thetas: np.ndarray) -> list[SnapshotSolve]:
        """Solve snapshots given as rows of data vectors (`data_vector`), one by one; the
        offsets before and the solutions' read-out after are done for all at once."""
        thetas = np.atleast_2d(thetas)
        raw = []
        for b in self.program.offsets(thetas):
            start = now()
            raw.append((self.program.solve(b), elapsed_ms(start)))  # Clarabel's own solve_time is not
            # used: after an in-place update it reads above the wall time of update + solve.
        solved = np.array([a.solved for a, _ in raw], dtype=bool)
        n_x = self.program.n_x
        final = [a for (a, _), ok in zip(raw, solved, strict=True) if ok]
        x = np.array([a.x for a in final]).reshape(-1, n_x)
        primal = np.array([a.primal for a in final])
        dual = np.array([a.dual for a in final])
        value = self.program.reader(x)
        n, n_der = self.net.n_bus, len(self.net.ders)
        p_pu = None
        if self.p is None:
            q_limit = thetas[solved, 2 * n :]
            q_pu = np.clip(value(self.q), -q_limit, q_limit)  # within solver tolerance of the limits anyway
            slack_p = self._slack_p_pu(value, thetas[solved], primal)
        else:  # the optimum: losses + curtailed = objective + ΣP; the slack's P as the objective carries it
            p_avail, p_low = thetas[solved, 2 * n : 2 * n + n_der], thetas[solved, 2 * n + n_der : 2 * n + 2 * n_der]
            q_pu, p_pu = value(self.q), np.clip(value(self.p), p_low, p_avail)
            slack_p = self._slack_p_pu(value, thetas[solved], primal)
            available = self.problem.kw_per_pu * p_avail.sum(axis=1)
            primal, dual = primal + available, dual + available
        residual = self._cone_residual(value)
        gap = np.full(primal.size, np.nan) if residual is None else residual
        out, j = [], 0
        for (a, solve_ms), ok in zip(raw, solved, strict=True):
            if not ok:
                outcome = "infeasible" if a.final_status in CONIC_INFEASIBLE else "failed"
                out.append(SnapshotSolve(outcome, a.status, np.nan, None, np.nan, solve_ms, a.iterations, a.solves))
                continue
            out.append(
                SnapshotSolve(
                    "optimal",
                    a.status,
                    float(min(primal[j], dual[j])),
                    q_pu[j],
                    float(gap[j]),
                    solve_ms,
                    a.iterations,
                    a.solves,
                    float(slack_p[j]),
                    None if p_pu is None else p_pu[j],
                )
            )
            j += 1
        return out
