"""Second-order-cone relaxation of the loss-minimizing reactive dispatch (cvxpy + Clarabel).

The OPF problem of `problem.OpfProblem` (as the AC OPF solves it), in v = |V|²: DER Q
within ±(1 − k)·Qmax(P), v_slack², vmin² ≤ v ≤ vmax², the power balance and slack rule
of `OpfProblem.balance`; objective = branch losses. Two relaxations of the voltage coupling:

- **DistFlow** (branch flow model, Baran–Wu / Farivar–Low), radial feeders. Per branch
  from parent i to child j: sending-end flow P + jQ into the series impedance r + jx,
  squared series current ℓ; v_j = v_i − 2(rP + xQ) + (r² + x²)ℓ, and the relaxation
  P² + Q² ≤ v_i·ℓ of P² + Q² = v_i·ℓ. Line charging b is exact as a shunt b/2 at both
  ends (π model); bus shunts Gs/Bs exact. Transformers (real grids'): a tap ratio τ sits
  at the branch's from end, so that end's voltage enters the branch as v/τ² (in the drop,
  the cone and its shunts b/2, g/2 — the π model's shunt conductance g, e.g. iron losses,
  counted in the losses like the series r·ℓ); a phase shift only rotates the angles of a
  radial feeder, which DistFlow does not model, so it changes nothing. The cone is written
  per branch as ‖(2P/√α, 2Q/√α, v_i − ℓ/α)‖ ≤ v_i + ℓ/α, the same set for any α > 0,
  with α = (what the branch may carry)² (`branch_scale`): ℓ/α is then of order one
  like v_i. Unscaled, a branch carrying 1e-5 of a feeder's power has ℓ ~ 1e-10 next to
  v ~ 1 and Clarabel stalls (feeder10k at noon, k = 0: 200 iterations, "AlmostSolved",
  bound −4 to −360 kW against a 25.56 kW optimum; scaled: "Solved" in 12 iterations).
- **Jabr** (bus injection SOC), any feeder: W = V·Vᴴ on the branches, v_i = W_ii,
  c + js = W_ft, flows linear in (v, c, s) for the general π model with taps/shifts,
  relaxation c² + s² ≤ v_f·v_t (the angle-cycle conditions of meshes are dropped).

Any AC-feasible point maps to a feasible point of either relaxation with the same
losses, so the optimum is a lower bound on the AC OPF's. The bound reported is
min(primal, dual) objective of Clarabel's solution (kW). Clarabel's "AlmostSolved"
(reduced tolerances met) counts as solved and is recorded as such in solver_status; a
solve that stalls after an in-place data update is retried once on a fresh solver
(`conic.ParametricConeProgram.solve`), recorded as e.g. "InsufficientProgress → Solved".

`relaxation_gap` = max over branches of the cone residual at the optimum, in p.u.²:
v_i·ℓ − P² − Q² for DistFlow (squared apparent power on base_mva), v_f·v_t − c² − s²
for Jabr (squared voltage-product magnitude). 0 (in practice ≲ 1e-7, the solver's
tolerance) means the relaxation is exact on every branch (for Jabr on a meshed feeder
also the cycle condition would have to hold; the AC losses of the setpoints against the
bound is the end-to-end measure).

`socp_solves(scenario, k, ...)` solves every snapshot once per (Scenario object, k,
options) and hands the same solves to every caller (`run_socp`, and `run_acopf` for its
bound, certified fast path and fallback). Two further shares, each exact:

- identical data, one solve: a snapshot whose data (fixed injections, Q limits) equal a
  snapshot solved before in this process, under the same network and options, gets that
  solve (`SolveMemo`; e.g. the daytime steps of the three night modes). The solve is a
  function of its data alone (Clarabel setups updated in place; bound screening answers
  with the snapshot's own active set whatever was solved before, `conic`), so this changes
  no digit.
- the paper's slack rule from the unrestricted problem: the problem with slack P ≥ 0 is
  the unrestricted one with one more constraint, so where the unrestricted optimum already
  imports (slack P ≥ 0) it is the restricted optimum too, and where the unrestricted
  problem is infeasible so is the restricted one; only the other snapshots (the slack
  exports at the unrestricted optimum, or its solve failed) are solved again. The relaxation itself (cvxpy model + one
Clarabel instance) is built once per network and options *per thread*
(`cache.per_thread`); `build_socp` builds a new one for callers who want their own.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Literal

import clarabel
import cvxpy as cp
import numpy as np

from opfbench.errors import NetworkError
from opfbench.formulations.cache import per_scenario, per_thread
from opfbench.formulations.conic import INFEASIBLE as CONIC_INFEASIBLE
from opfbench.formulations.conic import ParametricConeProgram
from opfbench.formulations.problem import (
    FROM_NO_ACTION,
    FROM_SOLVER,
    SOLVER_FAILED,
    OpfProblem,
    Row,
    SnapshotData,
    check_option,
    diagnostics,
    evaluated_result,
    incidence,
    snapshot_data,
)
from opfbench.network import Network
from opfbench.result import INFEASIBLE, OK, StrategyResult
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now

Model = Literal["auto", "distflow", "jabr"]
MODELS = ("auto", "distflow", "jabr")
TOLERANCE = 1e-8  # Clarabel gap and feasibility tolerances (objective in kW)
MAX_ITER = 200


@dataclass(frozen=True)
class SocpSolve:
    """One snapshot's relaxation solve. outcome: "optimal" | "infeasible" (certified by
    Clarabel) | "failed"; solver_status: Clarabel's own status; solve_ms: wall time of
    Clarabel's data updates and solves; iterations: the answering Clarabel solve's; solves:
    every Clarabel solve the answer took (`conic.ConeSolve`); slack_p_pu: the
    slack bus's active injection at the optimum (p.u., positive = import from the upstream
    grid). Where not optimal, lower_bound_kw, relaxation_gap and slack_p_pu are NaN and
    q_pu is None."""

    outcome: str
    solver_status: str
    lower_bound_kw: float
    q_pu: np.ndarray | None
    relaxation_gap: float
    solve_ms: float
    iterations: int
    solves: int
    slack_p_pu: float = np.nan

    @property
    def optimal(self) -> bool:
        return self.outcome == "optimal"


def _rows(row: Row) -> list[cp.Constraint]:
    """A problem row lo ≤ expr ≤ hi as cvxpy constraints."""
    if np.array_equal(row.lo, row.hi):
        return [row.expr == row.lo]
    return ([row.expr >= row.lo] if np.all(np.isfinite(row.lo)) else []) + (
        [row.expr <= row.hi] if np.all(np.isfinite(row.hi)) else []
    )


class SocpRelaxation:
    """The relaxation of one `OpfProblem`, built once; `solve` per snapshot.

    Data (cvxpy variables that `conic.ParametricConeProgram` holds fixed per solve):
    p_fixed, q_fixed (n_bus,) fixed injections and q_limit (n_der,) usable Q limit, all
    p.u. Subclasses add the network model.
    """

    model: str = ""

    def __init__(self, net: Network, slack_export: bool = True):
        self.problem = problem = OpfProblem.of(net, slack_export)
        self.net = net
        n = net.n_bus
        self.p_fixed = cp.Variable(n, name="p_fixed")
        self.q_fixed = cp.Variable(n, name="q_fixed")
        self.q_limit = cp.Variable(len(net.ders), name="q_limit")
        self.q = cp.Variable(len(net.ders), name="q_der")
        self.v = cp.Variable(n, name="v")  # |V|² p.u.²
        mismatch_p, mismatch_q, losses, constraints = self._network_model()
        others = problem.others
        for row in problem.balance(mismatch_p, mismatch_q, lambda e, i: e[i]):
            constraints += _rows(row)
        constraints += [
            self.v[problem.slack] == problem.v_slack**2,
            self.v[others] >= problem.vm_min**2,
            self.v[others] <= problem.vm_max**2,
            self.q <= self.q_limit,
            self.q >= -self.q_limit,
        ]
        self.cvxpy_problem = cp.Problem(cp.Minimize(problem.kw_per_pu * losses), constraints)
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.max_iter = MAX_ITER
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = TOLERANCE
        # Measured on the paper day (paper33, 1440 solves): iterative refinement doubled the
        # solve time (1.99 → 1.01 ms) for objectives within 2e-6 kW; one thread and QDLDL
        # (deterministic, no thread pool on tiny KKT systems) another ~10 %.
        settings.iterative_refinement_enable = False
        settings.max_threads = 1
        settings.direct_solve_method = "qdldl"
        # Mean Clarabel iterations per answer on the paper day at k = 0 / 0.4 (screened, as
        # solved), step fraction 0.99 (Clarabel's default) → 0.98: paper33 10.5 → 9.4 / 11.1 →
        # 8.9, case69-der 9.9 → 9.5 / 10.1 → 9.7, case141-der 9.5 → 9.9 / 9.4 → 9.5, feeder1k
        # (every 20th step) 11.1 → 9.9 / 10.7 → 10.1; 0.97: more again.
        settings.max_step_fraction = 0.98
        self.program = ParametricConeProgram(
            self.cvxpy_problem, (self.p_fixed, self.q_fixed, self.q_limit), settings, screening=screens(net)
        )

    def _network_model(self) -> tuple[cp.Expression, cp.Expression, cp.Expression, list[cp.Constraint]]:
        """(mismatch_p, mismatch_q, branch losses, model constraints), p.u., per `problem`."""
        raise NotImplementedError

    def _cone_residual(self, value) -> np.ndarray:
        """Largest cone residual of each of stacked solutions; `value(var)` reads a variable
        as (S, size)."""
        raise NotImplementedError

    def _der_q_at_buses(self) -> cp.Expression:
        return self.problem.der_at_bus @ self.q

    def solve(self, s_fixed: np.ndarray, q_limit: np.ndarray) -> SocpSolve:
        """Solve one snapshot: fixed injections `s_fixed` (n_bus,) complex p.u., usable
        Q limits `q_limit` (n_der,) p.u."""
        return self.solve_data(data_vector(s_fixed, q_limit)[None])[0]

    def solve_data(self, thetas: np.ndarray) -> list[SocpSolve]:
        """Solve snapshots given as rows of data vectors (`data_vector`), one by one; the
        offsets before and the solutions' read-out after are done for all at once."""
        thetas = np.atleast_2d(thetas)
        raw = []
        for b in self.program.offsets(thetas):
            start = now()
            raw.append((self.program.solve(b), elapsed_ms(start)))  # Clarabel's own solve_time is not
            # used: after an in-place update it reads ~0.2 ms above the wall time of update + solve.
        solved = np.array([a.solved for a, _ in raw], dtype=bool)
        n_x = self.program.n_x
        final = [a for (a, _), ok in zip(raw, solved, strict=True) if ok]
        x = np.array([a.x for a in final]).reshape(-1, n_x)
        primal = np.array([a.primal for a in final])
        dual = np.array([a.dual for a in final])
        value = self.program.reader(x)
        n, q_limit = self.net.n_bus, thetas[solved, 2 * self.net.n_bus :]
        q_pu = np.clip(value(self.q), -q_limit, q_limit)  # within solver tolerance of the limits anyway
        # Summed over all buses the mismatches are the branch losses plus the shunts' P minus
        # the fixed injections; every non-slack mismatch is 0, so this is the slack's P.
        slack_p = primal / self.problem.kw_per_pu + value(self.v) @ self.problem.gsh - thetas[solved, :n].sum(axis=1)
        gap = self._cone_residual(value)
        out, j = [], 0
        for (a, solve_ms), ok in zip(raw, solved, strict=True):
            if not ok:
                outcome = "infeasible" if a.final_status in CONIC_INFEASIBLE else "failed"
                out.append(SocpSolve(outcome, a.status, np.nan, None, np.nan, solve_ms, a.iterations, a.solves))
                continue
            out.append(
                SocpSolve(
                    "optimal",
                    a.status,
                    float(min(primal[j], dual[j])),
                    q_pu[j],
                    float(gap[j]),
                    solve_ms,
                    a.iterations,
                    a.solves,
                    float(slack_p[j]),
                )
            )
            j += 1
        return out


class DistFlowSocp(SocpRelaxation):
    """Branch-flow (DistFlow) relaxation for radial feeders; see the module docstring."""

    model = "distflow"

    def _network_model(self):
        net = self.net
        if net.meshed:
            raise NetworkError(f"{net.name}: DistFlow needs a radial feeder; this one is meshed (use the Jabr model)")
        on = np.flatnonzero(net.status)
        child = net.bfs_order[net.bfs_order != net.slack]
        parent, branch = net.parent[child], net.parent_branch[child]
        n, m = net.n_bus, child.size
        at_child, at_parent = incidence(child, n), incidence(parent, n)
        r, x = net.r[branch], net.x[branch]
        tapped = bool((net.tap[on] != 1.0).any())
        from_scale = 1.0 / net.tap[on] ** 2 if tapped else 1.0  # the from end's shunts see v/τ²
        charging = np.zeros(n)  # π-model line charging as bus shunts, b/2 at each end
        np.add.at(charging, net.f[on], net.b[on] / 2 * from_scale)
        np.add.at(charging, net.t[on], net.b[on] / 2)
        conductance = np.zeros(n)  # π-model shunt conductance g/2 at each end (branch losses)
        if net.g[on].any():
            np.add.at(conductance, net.f[on], net.g[on] / 2 * from_scale)
            np.add.at(conductance, net.t[on], net.g[on] / 2)
        self.p_br = cp.Variable(m, name="p_branch")
        self.q_br = cp.Variable(m, name="q_branch")
        self.l_br = cp.Variable(m, name="l_branch")  # |I|² p.u.²
        v, p_br, q_br, l_br = self.v, self.p_br, self.q_br, self.l_br
        v_parent, v_child = v[parent], v[child]
        if tapped:  # v/τ² at the from end of each branch (parent or child side)
            at_tap = 1.0 / net.tap[branch] ** 2
            from_is_parent = net.f[branch] == parent
            self._parent_scale = np.where(from_is_parent, at_tap, 1.0)
            v_parent = cp.multiply(self._parent_scale, v_parent)
            v_child = cp.multiply(np.where(from_is_parent, 1.0, at_tap), v_child)
        else:
            self._parent_scale = np.ones(m)
        inv_s = 1 / branch_scale(net)[child]  # the cone's per-branch scale: α = 1 / inv_s²
        l_scaled = cp.multiply(inv_s**2, l_br)  # ℓ/α
        shunt_p = cp.multiply(self.problem.gsh + conductance, v) if conductance.any() else cp.multiply(self.problem.gsh, v)
        mismatch_p = at_parent @ p_br - at_child @ (p_br - cp.multiply(r, l_br)) + shunt_p - self.p_fixed
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

    def _cone_residual(self, value) -> np.ndarray:
        v_par = value(self.v)[:, self._parent] * self._parent_scale
        p, q, l_ = value(self.p_br), value(self.q_br), value(self.l_br)
        return np.max(v_par * l_ - p**2 - q**2, axis=1, initial=0.0)


def screens(net: Network) -> bool:
    """Whether the relaxation of `net` uses bound screening (`conic`): not on feeders with
    a DER at every other bus or more (SimBench's MV grids). There the active set moves with
    almost every 15-min step and is often degenerate — measured on 1-MV-rural's paper day
    (102 DER, 101 buses): the last step's guess failed on 73 % of the steps and the screened
    program at a step's own active set passed its check on 43 %, ~3 Clarabel solves per
    step (8.0 ms) against one full solve (2.2 ms)."""
    return len(net.ders) < net.n_bus / 2


def branch_scale(net: Network) -> np.ndarray:
    """Per bus (radial feeder), p.u. on `net.base_mva`: the apparent power its parent
    branch may carry — the larger of the nominal load |S| and the DER rating below it —
    floored at 1e-3 of the largest (1 where nothing is below any branch). The slack's
    entry is unused. The floor matters where (almost) nothing is below a branch: its
    ℓ ≈ 0, and a tiny α would magnify solver noise (case141-der, paper day: 18.4
    iterations per solve with a 1e-6 floor, 13.5 with 1e-3, 10.4 unscaled)."""
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


class JabrSocp(SocpRelaxation):
    """Bus-injection (Jabr) SOC relaxation for any feeder; see the module docstring."""

    model = "jabr"

    def _network_model(self):
        br = self.problem.branches
        self.c_br = cp.Variable(br.n_branch, name="c_branch")  # Re V_f·conj(V_t)
        self.s_br = cp.Variable(br.n_branch, name="s_branch")  # Im V_f·conj(V_t)
        vf, vt = self.v[br.f], self.v[br.t]
        p_f, q_f, p_t, q_t = br.flows(vf, vt, self.c_br, self.s_br, cp.multiply)
        mismatch_p = br.at_from @ p_f + br.at_to @ p_t + cp.multiply(self.problem.gsh, self.v) - self.p_fixed
        mismatch_q = (
            br.at_from @ q_f + br.at_to @ q_t - cp.multiply(self.problem.bsh, self.v) - self.q_fixed - self._der_q_at_buses()
        )
        cone = cp.SOC(vf + vt, cp.vstack([2 * self.c_br, 2 * self.s_br, vf - vt]), axis=0)
        return mismatch_p, mismatch_q, cp.sum(p_f + p_t), [cone]

    def _cone_residual(self, value) -> np.ndarray:
        br = self.problem.branches
        v = value(self.v)
        c, s = value(self.c_br), value(self.s_br)
        return np.max(v[:, br.f] * v[:, br.t] - c**2 - s**2, axis=1, initial=0.0)


def resolve_model(net: Network, model: Model) -> str:
    """ "auto" → DistFlow on radial feeders, Jabr on meshed ones."""
    check_option("SOCP model", model, MODELS)
    return ("jabr" if net.meshed else "distflow") if model == "auto" else model


def build_socp(net: Network, slack_export: bool = True, model: Model = "auto") -> SocpRelaxation:
    """A new relaxation of `net` (the caller's own: its Clarabel instance is mutable)."""
    return {"distflow": DistFlowSocp, "jabr": JabrSocp}[resolve_model(net, model)](net, slack_export)


def relaxation(net: Network, slack_export: bool = True, model: Model = "auto") -> SocpRelaxation:
    """The relaxation of `net`, built once per network and options in this thread."""
    model = resolve_model(net, model)
    return per_thread(net, ("socp", bool(slack_export), model), lambda: build_socp(net, slack_export, model))


def data_vector(s_fixed: np.ndarray, q_limit: np.ndarray) -> np.ndarray:
    """A snapshot's data θ = [Re s_fixed, Im s_fixed, q_limit] (p.u.); `s_fixed`/`q_limit`
    may be one snapshot or (S, ·) arrays."""
    return np.concatenate([s_fixed.real, s_fixed.imag, q_limit], axis=-1)


class SolveMemo:
    """Solves by their data, per (network, options), in this process: least recently used
    entries beyond MEMO_BYTES (estimated) are dropped. Keys are 128-bit BLAKE2 digests of θ."""

    ENTRY_BYTES = 400  # a SocpSolve without its q_pu array, with its key (estimate)

    def __init__(self, limit_bytes: int):
        self.limit, self.used = limit_bytes, 0
        self._entries: OrderedDict[tuple, SocpSolve] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def key(net: Network, options: tuple, theta: np.ndarray) -> tuple:
        return net, options, hashlib.blake2b(theta.tobytes(), digest_size=16).digest()

    @classmethod
    def _size(cls, solve: SocpSolve) -> int:
        return cls.ENTRY_BYTES + (solve.q_pu.nbytes if solve.q_pu is not None else 0)

    def get(self, key: tuple) -> SocpSolve | None:
        with self._lock:
            solve = self._entries.get(key)
            if solve is not None:
                self._entries.move_to_end(key)
            return solve

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self.used = 0

    def put(self, key: tuple, solve: SocpSolve) -> None:
        with self._lock:
            if key in self._entries:
                return
            self._entries[key] = solve
            self.used += self._size(solve)
            while self.used > self.limit and len(self._entries) > 1:
                self.used -= self._size(self._entries.popitem(last=False)[1])


MEMO_BYTES = 256 * 2**20
_memo = SolveMemo(MEMO_BYTES)


def forget_solves() -> None:
    """Empty this process's memo of solves by data (benchmarks timing the solves themselves)."""
    _memo.clear()


def _restricted(unrestricted: SocpSolve) -> SocpSolve | None:
    """The slack-may-not-export problem's solve where the unrestricted one settles it (see
    the module docstring), else None."""
    if unrestricted.outcome == "infeasible" or (unrestricted.optimal and unrestricted.slack_p_pu >= 0.0):
        return unrestricted
    return None


def socp_solves(
    scenario: Scenario, k: float, slack_export: bool = True, model: Model = "auto", data: SnapshotData | None = None
) -> tuple[SocpSolve, ...]:
    """The relaxation solved on every snapshot of `scenario` with reserve k — once per
    (scenario object, k, options); every later caller gets the same solves; identical data
    and the paper's slack rule share solves as the module docstring says. `data`: the
    scenario's `snapshot_data(scenario, k)` when the caller has it."""
    model = resolve_model(scenario.net, model)
    data = snapshot_data(scenario, k) if data is None else data

    def solve_all() -> tuple[SocpSolve, ...]:
        net = scenario.net
        relax = relaxation(net, slack_export, model)
        unrestricted = None if slack_export else socp_solves(scenario, k, True, model, data)
        thetas = data_vector(data.s_fixed, data.q_limit)
        keys = [SolveMemo.key(net, (bool(slack_export), model), theta) for theta in thetas]
        out = [_memo.get(key) for key in keys]
        for i, solve in enumerate(out):
            if solve is None and unrestricted is not None:
                out[i] = _restricted(unrestricted[i])
        missing = [i for i, solve in enumerate(out) if solve is None]
        first = {}  # a snapshot's data seen before in this scenario: solved once
        for i in missing:
            first.setdefault(keys[i], i)
        todo = sorted(set(first.values()))
        for i, solve in zip(todo, relax.solve_data(thetas[todo]) if todo else [], strict=True):
            out[i] = solve
        for i in range(len(out)):
            out[i] = out[i] or out[first[keys[i]]]
            _memo.put(keys[i], out[i])
        return tuple(out)

    return per_scenario(scenario, ("socp", float(k), bool(slack_export), model), solve_all)


def run_socp(scenario: Scenario, k: float, *, slack_export: bool = True, model: Model = "auto") -> StrategyResult:
    """The relaxation's setpoints on every snapshot, evaluated by the AC power flow.

    Status "ok" where Clarabel solved it, "infeasible" where it certified infeasibility
    (then no action, Q = 0, which also proves the AC OPF infeasible), "solver-failed"
    otherwise (also Q = 0). lower_bound_kw: the relaxation bound (NaN where not solved).
    extra: solve_ms, iterations, solves, solver_status (Clarabel's), relaxation_gap, fallback,
    certified_by ("" — the relaxation's point is not certified optimal for the AC OPF;
    `run_acopf` does that), model.
    """
    start = now()
    data = snapshot_data(scenario, k)
    model = resolve_model(scenario.net, model)
    solves = socp_solves(scenario, k, slack_export, model, data)
    n_der = len(scenario.net.ders)
    q_pu = np.array([s.q_pu if s.optimal else np.zeros(n_der) for s in solves]).reshape(len(solves), n_der)
    status = np.array(
        [OK if s.optimal else INFEASIBLE if s.outcome == "infeasible" else SOLVER_FAILED for s in solves], dtype=object
    )
    extra = diagnostics(
        socp_diagnostics(s) | {"fallback": FROM_SOLVER if s.optimal else FROM_NO_ACTION, "certified_by": "", "model": model}
        for s in solves
    )
    return evaluated_result(
        "socp",
        k,
        scenario,
        OpfProblem.of(scenario.net, slack_export),
        data,
        q_pu,
        elapsed_ms(start),
        status,
        np.array([s.lower_bound_kw for s in solves]),
        extra,
    )


def socp_diagnostics(s: SocpSolve) -> dict:
    """The per-snapshot diagnostics a relaxation solve contributes to a result's `extra`."""
    return {
        "solve_ms": s.solve_ms,
        "iterations": int(s.iterations),
        "solves": int(s.solves),
        "solver_status": s.solver_status,
        "relaxation_gap": s.relaxation_gap,
    }
