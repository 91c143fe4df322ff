"""The frontier of losses against voltage compliance: the AC OPF, and its certified bound,
with every bus's voltage band widened by ε on a small grid (`EPSILONS`, p.u.; ∞ = within
the physical limits alone, 0 ≤ |V| ≤ `V_LIMIT_MAX_PU`), computed once per scenario and k
and read by every rule of a study.

Why: a rule that leaves the band can save more losses than the optimum that holds it, so
the optimum's losses are no reference for it. The optimum with the band widened by ε is
a lower bound for every operating point whose excursion beyond the band is at most ε. A
rule's step is compared with the frontier point at the smallest grid ε that covers the
rule's own excursion at that step (`Frontier.at`): its gap there is never negative, up to
the optimum being global (certified by the relaxation almost everywhere; IPOPT's local
optimum elsewhere) and the rule's point lying in the OPF's set (within the capability the
OPF's DER may use, below; its active power its own).

With `curtail` the frontier is that of the AC OPF that may curtail (`acopf:curtail=true`:
objective losses + curtailed power): the reference of a configuration at the steps where
it curtails (Volt-Watt, reactive priority), whose points lie in its set and not in the
plain one's (`reference`); at its other steps the plain frontier's point bounds it.

The capability a step used (`Part`, `reference`; the study picks each step's frontier). The
OPF at reserve k lets every DER use (1 − k)·Qmax(P) at the power P it delivers (limit
RESERVE). A rule's setpoint may use more: Algorithm 3 (`strategies.limits`) evaluates the
limit at the forecast P^F too and so eats into the reserve — by design: the reserve k is an
operator's policy for fault ride-through, which the paper trades for losses where the
forecast says the capability will be there; the inverter can deliver such a point, for it
lies within its capability Qmax(P^C). Such a step is compared with the frontier at the
capability its setpoints used — the OPF whose DER may use Algorithm 3's limit of the rule's
forecast source, capped at Qmax(P^C) (limit FORECAST, a scenario's `q_limit_mvar`: one
frontier per forecast source, shared by every rule reading it) —, or, where a setpoint
exceeds even that (or the rule curtails too), with the frontier at k = 0, the full
capability (limit CAPABILITY). A setpoint beyond Qmax(P^C) itself (Algorithm 3 without
`safe`, e.g. Q from a PV unit whose power is still 0 at dawn while the forecast says it
rises) is one no inverter delivers — it cannot exceed its rating — and lies in no OPF's
set: no frontier point bounds it, so the step has no reference (NaN: a step without one,
and the period gets no gap or share at equal compliance; `safe=true` caps the limit at
Qmax(P^C)). So each step's reference is a lower bound for every operating point a rule
can reach, at the tightest of these sets that holds it.

The frontier point at ε = 0 is the `acopf` strategy's own answer (passed in where the run
has it). Widening a band that does not bind changes no optimum: where the ε = 0 optimum
keeps every |V| at least `MARGIN_PU` inside its limits it is the point at every ε, and only
the other steps are solved again — first with the widest band, whose optimum (excursion
e*) is the point at every ε ≥ e*, then at each grid ε below e*, largest first, each
answer also covering the smaller ε its own excursion stays within, and an answer whose
infeasibility is proven (the relaxation certified it, or the interval bounds did:
`proven_infeasible` in its extra) covering every smaller ε — a narrower band only removes
points, so no point exists there either, and the answer is the same: no action, no
bound. Each ε is solved by the
AC OPF on the network with its band widened (`widened`), its fast path and fallback chain
included; an answer counts as the optimum where its status is "ok" or "fallback-cold" (a
solver's optimum), else the step has no optimum at that ε (infeasible, or only a fallback
point), and its bound where the relaxation was solved. On a three-phase feeder the
frontier's points carry no bound (NaN): its SDP relaxation costs seconds a step, and the
leaderboard's own AC OPF rows bound their stated sample (`three_phase.bound_sample`).

Units: kW, p.u.; costs are losses (active power the DER curtail, where a formulation may
curtail, added).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from opfbench.formulations.acopf_options import AcopfSolver
from opfbench.multiphase import PhaseNetwork
from opfbench.network import V_LIMIT_MAX_PU, Network
from opfbench.result import FALLBACK_COLD, OK, Reference, StrategyResult
from opfbench.scenario import Scenario

#: The grid of band widenings ε (p.u.), smallest first; the last is ∞ (the physical limits).
EPSILONS: tuple[float, ...] = (0.0, 0.0025, 0.005, 0.01, 0.02, 0.05, math.inf)
COVER_PU = 1e-6  # an excursion up to ε + this is covered by ε (the OPF's voltage tolerance)
MARGIN_PU = 1e-6  # an optimum this far inside every limit does not bind its band
OPTIMA = (OK, FALLBACK_COLD)  # statuses whose point is a solver's optimum
RESERVE_MVAR = 1e-7  # a setpoint this far beyond a limit exceeds it (the rule engine's Q tolerance)
CAPABILITY_MVAR = 1e-9  # a setpoint this far beyond Qmax exceeds the capability (`excursion_steps`' threshold)
#: What a frontier's DER may use (`Frontier.limit`, module docstring): (1 − k)·Qmax(P), the
#: reserve kept; a forecast source's Algorithm 3 limit (capped at Qmax(P^C)); Qmax(P) (k = 0).
RESERVE, FORECAST, CAPABILITY = "reserve", "forecast", "capability"
_WIDENED = 32  # widened networks kept per process (least recently used dropped)
_cache: OrderedDict[tuple[Network | PhaseNetwork, float], Network | PhaseNetwork] = OrderedDict()
NetT = TypeVar("NetT", Network, PhaseNetwork)
_lock = threading.Lock()


def widened(net: NetT, eps: float) -> NetT:
    """`net` with every bus's voltage band but the slack's widened by `eps` p.u. (vmin − ε ≥ 0,
    vmax + ε ≤ V_LIMIT_MAX_PU; ∞: those limits; a negative ε tightens it) — on a three-phase
    feeder its band at every monitored voltage (`PhaseNetwork.with_band`: the source's EMF
    is fixed behind its impedance, so no monitored voltage is held) —, one object per
    (network, ε) in this process so that the formulations' compiled programs and solves
    are shared by every caller."""
    if eps == 0:
        return net
    key = (net, float(eps))
    with _lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]  # type: ignore[return-value]
    out: Network | PhaseNetwork
    if isinstance(net, PhaseNetwork):
        lo, hi = net.band
        out = net.with_band(max(lo - eps, 0.0), min(hi + eps, V_LIMIT_MAX_PU))
    else:
        other = np.arange(net.n_bus) != net.slack  # the slack's |V| is held at its setpoint: its band stays
        vmin = np.maximum(net.vmin - eps, 0.0) if math.isfinite(eps) else np.zeros(net.n_bus)
        out = net.with_changes(
            vmin=np.where(other, vmin, net.vmin), vmax=np.where(other, np.minimum(net.vmax + eps, V_LIMIT_MAX_PU), net.vmax)
        )
    with _lock:
        out = _cache.setdefault(key, out)
        while len(_cache) > _WIDENED:
            _cache.popitem(last=False)
    return out  # type: ignore[return-value]


def excursion(net: Network | PhaseNetwork, vm: np.ndarray) -> np.ndarray:
    """(S,) the largest excursion (p.u.) of |V| `vm` (S, n_bus) beyond `net`'s voltage
    limits, 0 where within; NaN where `vm` is NaN (no converged flow)."""
    low = np.maximum(net.vmin - vm, 0.0)
    high = np.maximum(vm - net.vmax, 0.0)
    return np.maximum(low, high).max(axis=1)


@dataclass(frozen=True)
class Frontier:
    """The frontier of one scenario at one k. Arrays (S, n_ε): `cost_kw` the optimum's
    losses (+ curtailed power) at each ε, NaN where the step has no optimum there; `bound_kw`
    the relaxation's certified bound, NaN where not solved; `excursion_pu` the optimum's own
    largest excursion beyond the (unwidened) band; `status` the AC OPF's status of the
    point; `solved` whether the point was solved at this ε (False: taken from the answer of
    another ε that covers it). `eps` (n_ε,) the grid; `curtail` whether the optimum may
    curtail."""

    eps: np.ndarray
    cost_kw: np.ndarray
    bound_kw: np.ndarray
    excursion_pu: np.ndarray
    status: np.ndarray
    solved: np.ndarray
    curtail: bool = False
    limit: str = RESERVE

    @property
    def n_snapshots(self) -> int:
        return self.cost_kw.shape[0]

    def index(self, excursion_pu: np.ndarray) -> np.ndarray:
        """(S,) the smallest grid ε (its index) covering each step's excursion; −1 where the
        excursion is NaN (no operating point to compare)."""
        e = np.asarray(excursion_pu, dtype=float)
        i = np.searchsorted(self.eps, np.nan_to_num(e, nan=0.0) - COVER_PU, side="left")
        return np.where(np.isnan(e), -1, np.minimum(i, self.eps.size - 1))

    def at(self, excursion_pu: np.ndarray, steps: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cost_kw, bound_kw, eps_pu), each (n,): the frontier point at the smallest grid ε
        covering each excursion, of the steps `steps` (default: 0, 1, … — an excursion per
        step); NaN where the excursion is NaN."""
        i = self.index(excursion_pu)
        rows = np.arange(i.size) if steps is None else np.asarray(steps)
        pick = np.maximum(i, 0)
        missing = i < 0
        cost = np.where(missing, np.nan, self.cost_kw[rows, pick])
        bound = np.where(missing, np.nan, self.bound_kw[rows, pick])
        return cost, bound, np.where(missing, np.nan, self.eps[pick])


@dataclass(frozen=True)
class Part:
    """A frontier computed on some of a task's steps, `rows` (sorted): the reference of a
    configuration at those of its steps that lie outside the plain frontier's set (module
    docstring) — it curtails (`front.curtail`), or its setpoints used its reserve
    (`front.limit` FORECAST or CAPABILITY)."""

    front: Frontier
    rows: np.ndarray

    def at(self, excursion_pu: np.ndarray, where: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`Frontier.at` for the steps `where` (task rows, each among `rows`) at their excursions."""
        at = np.searchsorted(self.rows, where)
        if where.size and (at.max() >= self.rows.size or not np.array_equal(self.rows[at], where)):
            raise ValueError("a partial frontier lacks a step it is the reference of")
        return self.front.at(excursion_pu, at)


def capability(scenario: Scenario, res: StrategyResult) -> np.ndarray:
    """(S, n_der) MVAr: each DER's capability Qmax at the power it delivered in `res`."""
    return scenario.qmax_mvar(
        scenario.der_p_mw if res.curtailed_mw is None else scenario.der_p_mw - np.nan_to_num(res.curtailed_mw)
    )


def within(res: StrategyResult, limit_mvar: np.ndarray, tolerance: float = RESERVE_MVAR) -> np.ndarray:
    """(S,) bool: every setpoint of `res` within ±`limit_mvar` (S, n_der), up to `tolerance` MVAr."""
    with np.errstate(invalid="ignore"):
        return (np.abs(res.q_mvar) <= limit_mvar + tolerance).all(axis=1)


def reference(
    plain: Frontier,
    excursion_pu: np.ndarray,
    parts: Sequence[tuple[Part, np.ndarray]] = (),
    unbounded: np.ndarray | None = None,
) -> Reference:
    """Each step's frontier point at its excursion (`Frontier.at`): the plain frontier's, and
    for each (part, steps) of `parts` — `steps` (S,) bool, a later part winning — the part's
    point at those steps; NaN (limit "") at the `unbounded` steps (S,) bool: setpoints beyond
    the capability, which no frontier bounds."""
    exc = np.asarray(excursion_pu, dtype=float)
    cost, bound, eps = (a.copy() for a in plain.at(exc))
    curtails = np.zeros(cost.size, dtype=bool)
    limit = np.full(cost.size, plain.limit, dtype=object)
    for part, steps in parts:
        where = np.flatnonzero(steps)
        if where.size:
            cost[where], bound[where], eps[where] = part.at(exc[where], where)
            curtails[where], limit[where] = part.front.curtail, part.front.limit
    if unbounded is not None and unbounded.any():
        cost[unbounded], bound[unbounded], eps[unbounded], limit[unbounded] = np.nan, np.nan, np.nan, ""
    return Reference(cost, bound, eps, curtails, limit)


def _cost(res: StrategyResult) -> np.ndarray:
    """(S,) the optimum's cost where `res`'s point is a solver's optimum, else NaN."""
    optimum = np.isin(res.status.astype(str), OPTIMA)
    return np.where(optimum, res.losses_kw + np.nan_to_num(res.curtailed_kw), np.nan)


def _bound(res: StrategyResult) -> np.ndarray:
    """(S,) the relaxation's bound of each step (NaN where it was not solved)."""
    raw = res.extra.get("relaxation_bound_kw")
    return np.full(res.n_snapshots, np.nan) if raw is None else np.asarray(raw, dtype=float)


def _proven_infeasible(res: StrategyResult) -> np.ndarray:
    """(S,) the steps whose infeasibility `res` proved (by the relaxation or the interval
    bounds, not a solver's report: `policy.Settled`)."""
    return np.asarray(res.extra.get("proven_infeasible", np.zeros(res.n_snapshots, dtype=bool)), dtype=bool)


def _binds(net: Network | PhaseNetwork, res: StrategyResult) -> np.ndarray:
    """(S,) whether a step's ε = 0 answer may depend on its band: not an optimum, or some
    |V| within MARGIN_PU of a limit."""
    vm = res.vm
    with np.errstate(invalid="ignore"):
        inside = ((vm >= net.vmin + MARGIN_PU) & (vm <= net.vmax - MARGIN_PU)).all(axis=1)
    return ~(inside & np.isin(res.status.astype(str), OPTIMA))


def frontier(
    scenario: Scenario,
    k: float,
    at_zero: StrategyResult | None = None,
    eps: tuple[float, ...] = EPSILONS,
    curtail: bool = False,
    limit: str = RESERVE,
) -> Frontier:
    """The frontier of `scenario` at reserve k (module docstring); `at_zero`: the AC OPF's
    result on the same scenario and k (with the same `curtail`), where the caller has it;
    `limit` says what the DER may use (recorded; the scenario and k give it)."""
    from opfbench.formulations.opf_strategies import run_acopf

    grid = np.asarray(eps, dtype=float)
    if grid[0] != 0 or np.any(np.diff(grid) <= 0):
        raise ValueError(f"the frontier's ε grid must start at 0 and increase, got {eps}")
    net = scenario.net
    solver: AcopfSolver = "ipopt" if scenario.three_phase else "auto"  # module docstring: no SDP
    n, m = scenario.n_snapshots, grid.size
    cost, bound = np.full((n, m), np.nan), np.full((n, m), np.nan)
    exc = np.full((n, m), np.nan)
    status = np.full((n, m), "", dtype=object)
    solved = np.zeros((n, m), dtype=bool)

    def record(rows: np.ndarray, res: StrategyResult, at: int) -> np.ndarray:
        """Store `res` (the answer at ε index `at` on `rows`) wherever it covers an ε ≤ that
        is still empty (its excursion within it, or its infeasibility proven); returns its
        excursions."""
        e = excursion(net, res.vm)
        first = np.searchsorted(grid, np.nan_to_num(e, nan=np.inf) - COVER_PU, side="left")
        proven = _proven_infeasible(res)
        for j in range(at + 1):
            fill = np.ones(rows.size, dtype=bool) if j == at else ((first <= j) | proven) & (status[rows, j] == "")
            r = rows[fill]
            cost[r, j], bound[r, j], exc[r, j] = _cost(res)[fill], _bound(res)[fill], e[fill]
            status[r, j] = res.status[fill]
            solved[r, j] = j == at
        return e

    zero = at_zero if at_zero is not None else run_acopf(scenario, k, curtail=curtail, solver=solver)
    every = np.arange(n)
    record(every, zero, 0)
    binding = _binds(net, zero)
    free = every[~binding]  # ε = 0's optimum is every ε's
    for j in range(1, m):
        cost[free, j], bound[free, j], exc[free, j] = cost[free, 0], bound[free, 0], exc[free, 0]
        status[free, j] = status[free, 0]
    for j in range(m - 1, 0, -1):
        rows = every[binding & (status[:, j] == "")]
        if rows.size:
            part = replace(scenario.take(rows), net=widened(net, grid[j]))
            record(rows, run_acopf(part, k, curtail=curtail, solver=solver), j)
    return Frontier(grid, cost, bound, exc, status, solved, curtail, limit)


def tightened(scenario: Scenario, k: float, margin: float, q_mvar: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The AC OPF with every bus's band tightened by `margin` p.u. (the frontier below ε = 0),
    given the optimum at ε = 0 — setpoints `q_mvar` (S, n_der) MVAr, a solver's optimum at
    `ok` (S,): a step whose optimum keeps every |V| at least margin + MARGIN_PU inside its
    limits keeps it; the others are solved on the tightened network. Returns (Q (S, n_der)
    MVAr, ok (S,)): where the tightened problem has no optimum, the step's ε = 0 point and
    its `ok`."""
    from opfbench.formulations.opf_strategies import run_acopf
    from opfbench.powerflow import solve_pf_batch

    net = scenario.net
    width = np.delete(net.vmax - net.vmin, net.slack)  # the slack's |V| is held at its setpoint
    if not 0 < margin < float(width.min(initial=np.inf)) / 2:
        raise ValueError(f"a band can be tightened by a margin in (0, half its width), got {margin}")
    vm = np.asarray(solve_pf_batch(net, scenario.injections(q_mvar)).vm)
    with np.errstate(invalid="ignore"):
        inside = ((vm >= net.vmin + margin + MARGIN_PU) & (vm <= net.vmax - margin - MARGIN_PU)).all(axis=1)
    rows = np.flatnonzero(~(inside & ok))
    q, good = np.array(q_mvar, dtype=float), np.array(ok, dtype=bool)
    if rows.size:
        res = run_acopf(replace(scenario.take(rows), net=widened(net, -margin)), k)
        optimum = np.isin(res.status.astype(str), OPTIMA)
        q[rows[optimum]], good[rows[optimum]] = res.q_mvar[optimum], True
    return q, good
