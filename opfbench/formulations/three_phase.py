"""The OPF problem on three-phase feeders: its exact model's optimum on every snapshot,
confirmed by the three-phase power flow — every reported figure is the power flow's — and
the relaxation's lower bound that can certify it. The models are the ones declared for the
feeder's class (`model.model_for(role, net)`: "unbalanced-radial" or "unbalanced-meshed";
today `models.ac_three_phase` exact on both, `models.sdp_three_phase` the relaxation on
radial feeders only — a meshed feeder gets no bound, refused with NetworkError). The exact
model is built once per feeder and thread (`solver_cache.per_thread`, on the feeder a
widened band was derived from: `PhaseNetwork.origin` — the band is a per-solve input). An
accepted point is IPOPT's local optimum confirmed by the power flow; `bound` + `certify`
state per snapshot whether the relaxation certifies it, and `run_phase` records that in
the strategy's `certified_by` and lower bound as on balanced feeders (on a stated sample
of a long run's steps: `BOUND_SAMPLE`).

`bound` solves the relaxation per snapshot (compiled once); `certify` compares: a step is
certified when the optimum's losses are within `CERTIFY_RTOL` (relative) of the bound,
otherwise its gap is recorded; a step whose relaxation is infeasible is proven infeasible.

Per snapshot (`optimum`): the exact model warm from the previous snapshot's answer, then
(failure policy "chain") cold from the power flow's no-action point; a point is accepted
only when IPOPT converged (`ac_three_phase.OPTIONS`: to 1e-10, or until the losses stop
moving) and the power flow at its Q setpoints converges, meets the band (`BAND_TOL`) and
gives the model's losses within `CONFIRM_RTOL` — where no attempt is accepted IPOPT runs
once more cold from the power flow at the last attempt's setpoints (chain only). Otherwise the snapshot
falls back to no action (Q = 0) where that meets the band (status fallback-no-action),
else reports `infeasible` (IPOPT detected it: a local verdict) or `solver-failed`. Under
the paper's policy ("paper") IPOPT runs once (warm where it can). A snapshot where no DER
has Q to give (night, or k = 1) has no decision: its candidate is the power flow's point,
the optimum where it meets the band, `infeasible` where it does not (a local verdict, as
IPOPT's: another solution of the network's equations might meet the band); that no other
solution of the network's equations meets the constraints is proven where
`unique_point` proves it (`step_bounds`, which then certifies the step without the SDP).

`run_phase` is the strategy's side (`acopf` and `acopf-paper` on a three-phase scenario,
through `runner.run_model`): the setpoints of `optimum` — Q = 0 where there is none, as
on balanced feeders — evaluated by the power flow, with statuses and the solver record.

Units: MW, MVAr (Q positive = injected), losses in kW.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from opfbench.capability import check_reserve, qmax
from opfbench.errors import NetworkError
from opfbench.formulations.acopf_options import FALLBACKS, Fallback, check_option
from opfbench.formulations.evaluation import solver_record
from opfbench.formulations.model import built, load_models, model_for
from opfbench.formulations.models.ac_three_phase import ThreePhaseAc
from opfbench.formulations.problem import PqCapability, capability_offsets
from opfbench.formulations.solver_cache import per_thread
from opfbench.formulations.solvers.ipopt_adapter import IpoptSolve
from opfbench.formulations.unique_point import unique_point
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import PhaseFlowResult, solve_phase_flow, tapped
from opfbench.registry.specs import ModelSpec
from opfbench.result import (
    CERTIFIED_BY_SDP,
    CERTIFIED_BY_UNIQUE,
    FALLBACK_COLD,
    FALLBACK_NO_ACTION,
    FROM_COLD,
    FROM_NO_ACTION,
    FROM_SOLVER,
    INFEASIBLE,
    OK,
    SOLVER_FAILED,
    VM_ERROR,
    StrategyResult,
)
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now

CERTIFY_RTOL = 1e-6
"""An optimum within this (relative) of the relaxation's bound is certified."""
CONFIRM_RTOL = 1e-4
"""A model's point is accepted when the power flow's losses at its setpoints are within this
(relative) of the model's own: the two model the same feeder (the NLP's own point carries
IPOPT's constraint tolerance, which near-zero-impedance switches and regulators amplify;
the reported losses are the power flow's, at the NLP's setpoints)."""
BAND_TOL = 1e-6
"""p.u. by which an accepted point's monitored voltages may leave the band (round-off)."""
CURTAIL_SNAP_MW = 1e-6
"""MW: a DER the OPF that may curtail leaves less than this short of its power is taken at
its power (IPOPT's barrier stops short of the bound P ≤ P_avail by its tolerance; 1 W is
no curtailment)."""
NO_Q_TO_GIVE = "no Q to give: the power flow's point"  # solver_status of such a snapshot
BOUND_SAMPLE = 24
"""At most this many steps of a run get the relaxation's bound (`run_phase`): every step of
a run up to that length, else this many spread evenly over it, first and last included —
the SDP takes seconds a step where IPOPT takes milliseconds. The other steps record
`NOT_SAMPLED`, no bound, and are never certified — except the steps without a decision,
which are all checked by `unique_point` (a matrix product a step) and need no SDP where it
proves their point."""
UNIQUE = "no decision: the power flow's point is the only feasible one (unique_point)"  # sdp_status there
NOT_SAMPLED = "not in the bound's sample"  # sdp_status of a step `run_phase` does not bound
NO_RELAXATION = "no relaxation serves this feeder"  # sdp_status on a meshed feeder


@dataclass(frozen=True, eq=False)
class PhaseOptimum:
    """The OPF on S snapshots. Arrays (S,): `status` (opfbench.result statuses),
    `losses_kw` the power flow's at the reported setpoints (NaN where there is no
    operating point to report), `objective_kw` the exact model's optimum (NaN unless
    accepted),
    `iterations` and `solve_ms` (IPOPT's, summed over attempts), `vmin`/`vmax` (p.u., the
    monitored voltages; NaN with the losses), `solver_status` (IPOPT's per attempt, joined
    by " → "), `warm` (the first attempt was warm); `q_mvar` (S, n_der) the setpoints (0
    where there is no optimum); `flow` the power flow at those setpoints (Q = 0 where
    there is no optimum: the point a strategy reports there, under its status); `p_mw`
    (S, n_der) the power the DER deliver where the OPF may curtail (None otherwise)."""

    status: np.ndarray
    q_mvar: np.ndarray
    losses_kw: np.ndarray
    objective_kw: np.ndarray
    iterations: np.ndarray
    solve_ms: np.ndarray
    vmin: np.ndarray
    vmax: np.ndarray
    solver_status: np.ndarray
    warm: np.ndarray
    flow: PhaseFlowResult
    p_mw: np.ndarray | None = None


def q_limits(net: PhaseNetwork, der_p_mw: np.ndarray, k: float) -> np.ndarray:
    """(S, n_der) the usable |Q| (MVAr): (1 − k) × each unit's capability at its P."""
    check_reserve(k)
    if not net.ders:
        return np.zeros((der_p_mw.shape[0], 0))
    rating = np.array([d.rating_mw for d in net.ders])
    s = np.array([d.s_rated_mva for d in net.ders])
    return (1.0 - k) * qmax([d.kind for d in net.ders], der_p_mw, rating, s)


def optimum(
    net: PhaseNetwork,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    k: float = 0.0,
    *,
    q_limit_mvar: np.ndarray | None = None,
    fallback: Fallback = "chain",
    slack_export: bool = True,
    curtail_offsets: np.ndarray | None = None,
) -> PhaseOptimum:
    """The OPF on S snapshots (module docstring): load P and Q (S, n_load) at their law's
    reference, DER P (S, n_der), reserve k — or the usable |Q| `q_limit_mvar` (S, n_der)
    where the caller has it (a scenario's, "Q at night" included) —, the failure policy,
    whether the source may take power back; with `curtail_offsets` (S, n_der, 2) MW (the
    capability pieces' offsets, `problem.capability_offsets`) the OPF that may curtail
    (its objective losses + curtailed power; `models.ac_three_phase`). Checked before any
    work: k and the policy, then shapes and finite values (the power flow's checks)."""
    check_reserve(k)
    check_option("AC OPF failure policy", fallback, FALLBACKS)
    no_action = solve_phase_flow(net, load_p_mw, load_q_mvar, der_p_mw)  # checks shapes and values first
    n, n_der = no_action.n_snapshots, len(net.ders)
    load_p, load_q = (np.asarray(x, dtype=float).reshape(n, net.n_load) for x in (load_p_mw, load_q_mvar))
    der_p = np.asarray(der_p_mw, dtype=float).reshape(n, n_der)
    limit = q_limits(net, der_p, k) if q_limit_mvar is None else np.asarray(q_limit_mvar, dtype=float).reshape(n, n_der)
    groups = tap_groups(net, no_action)
    if groups[0][0] is not net:  # under tap control: each snapshot at its no-action taps, held
        parts = [
            (
                rows,
                optimum(
                    held,
                    load_p[rows],
                    load_q[rows],
                    der_p[rows],
                    k,
                    q_limit_mvar=limit[rows],
                    fallback=fallback,
                    slack_export=slack_export,
                    curtail_offsets=None if curtail_offsets is None else curtail_offsets[rows],
                ),
            )
            for held, rows in groups
        ]
        flows = [(rows, part.flow) for rows, part in parts]
        flow = PhaseFlowResult(  # the feeder under control, at the taps each snapshot held
            net, tap_positions=no_action.tap_positions, **_stitched(PhaseFlowResult, n, flows, skip=("net", "tap_positions"))
        )
        return PhaseOptimum(**_stitched(PhaseOptimum, n, parts, skip=("flow",)), flow=flow)
    load_models()
    origin = net.origin  # the model is built once for the feeder; the band is the solve's
    curtail = curtail_offsets is not None
    capability = PqCapability.of(net, k, base_mva=1.0)
    if curtail:
        spec = model_for("exact", origin)
        exact = per_thread(
            origin, (f"{spec.name}-curtail", slack_export), lambda: ThreePhaseAc(origin, slack_export, curtail=True)
        )
    else:
        exact = built(model_for("exact", origin), origin, slack_export)
    lo, hi = net.band
    status = np.empty(n, dtype=object)
    q = np.zeros((n, n_der))
    p = der_p.copy()
    objective = np.full(n, np.nan)
    iterations = np.zeros(n, dtype=int)
    solve_ms = np.zeros(n)
    solver_status = np.full(n, "", dtype=object)
    warm = np.zeros(n, dtype=bool)
    start = None
    in_band = no_action.converged & (lo - BAND_TOL <= no_action.vm.min(axis=1)) & (no_action.vm.max(axis=1) <= hi + BAND_TOL)
    if not slack_export:
        in_band &= no_action.source_kva.real >= 0  # no action is a point only where the source does not take power back
    for i in range(n):
        undecided = not limit[i].any() and not (curtail and (der_p[i] > 0).any())
        if undecided and no_action.converged[i]:  # no decision: the power flow's point is the candidate
            status[i] = OK if in_band[i] else INFEASIBLE
            objective[i] = no_action.losses_kw[i] if in_band[i] else np.nan
            solver_status[i] = NO_Q_TO_GIVE
            continue
        attempts: list[IpoptSolve] = []
        accepted: IpoptSolve | None = None
        snapshot = (load_p[i], load_q[i], der_p[i])
        starts: list[dict] = [{"start": start}] if start is not None else []
        if no_action.converged[i] and (fallback == "chain" or not starts):
            starts.append({"x0": exact.initial(no_action.v[i], der_p[i])})  # cold, from the power flow's point
        cap = (capability, curtail_offsets[i]) if curtail_offsets is not None else None
        for how in starts:
            attempts.append(exact.solve(*snapshot, limit[i], band=(lo, hi), capability=cap, **how))
            point = _setpoints(attempts[-1], der_p[i])
            if _accepted(net, attempts[-1], point, *snapshot, slack_export):
                accepted = attempts[-1]
                break
        restart = (
            _flow_start(net, exact, attempts[-1], snapshot) if accepted is None and fallback == "chain" and attempts else None
        )
        if restart is not None:  # cold again, from the power flow at the last attempt's setpoints
            attempts.append(exact.solve(*snapshot, limit[i], band=(lo, hi), capability=cap, x0=restart))
            point = _setpoints(attempts[-1], der_p[i])
            if _accepted(net, attempts[-1], point, *snapshot, slack_export):
                accepted = attempts[-1]
        iterations[i] = sum(a.iterations for a in attempts)
        solve_ms[i] = sum(a.solve_ms for a in attempts)
        solver_status[i] = " → ".join(a.status for a in attempts)
        warm[i] = bool(attempts) and attempts[0].warm
        if accepted is not None:
            start = accepted
            (q[i], p[i]), objective[i] = point, accepted.objective_kw
            status[i] = FALLBACK_COLD if attempts[0].warm and accepted is not attempts[0] else OK
        elif in_band[i]:
            status[i] = FALLBACK_NO_ACTION
        elif any(a.infeasible for a in attempts):
            status[i] = INFEASIBLE
        else:
            status[i] = SOLVER_FAILED
    flow = solve_phase_flow(net, load_p, load_q, p, q)
    settled = flow.converged & (status != INFEASIBLE) & (status != SOLVER_FAILED)
    return PhaseOptimum(
        status,
        q,
        np.where(settled, flow.losses_kw, np.nan),
        objective,
        iterations,
        solve_ms,
        np.where(settled, flow.vm.min(axis=1, initial=np.inf), np.nan),
        np.where(settled, flow.vm.max(axis=1, initial=-np.inf), np.nan),
        solver_status,
        warm,
        flow,
        p if curtail else None,
    )


def run_phase(
    model: ModelSpec,
    scenario: Scenario,
    k: float,
    *,
    name: str = "",
    slack_export: bool = True,
    fallback: Fallback = "chain",
    curtail: bool = False,
    bounded: bool = False,
) -> StrategyResult:
    """The exact model on every snapshot of a three-phase `scenario` (module docstring), the
    result named `name` (default: the model's); with `curtail` the one that may curtail
    (the result carries the power curtailed). The solver record: objective_kw (the
    model's cost where accepted: losses, plus the power curtailed), solver_status (IPOPT's
    per attempt; `NO_Q_TO_GIVE` where no DER has Q), fallback, certified_by
    (`CERTIFIED_BY_SDP` where the step is certified, else ""), iterations and solve_ms
    (IPOPT's, summed over attempts); extra: warm_start, ac_feasible (the reported point
    meets the band), slack_export.

    `bounded` (and not `curtail`: the relaxation bounds the losses alone): a lower bound
    (`step_bounds`) — at every step without a decision whose power-flow point is proven the
    only feasible one (`unique_point`), that point's losses (certified_by
    `CERTIFIED_BY_UNIQUE`); on `bound_sample`'s other steps the relaxation's bound —
    lower_bound_kw where the reported point meets the band, certified (`CERTIFIED_BY_SDP`)
    as on balanced feeders where the point's losses are within CERTIFY_RTOL of it; extra
    relaxation_bound_kw, sdp_status (the solver's, `UNIQUE`, `NOT_SAMPLED` or
    `NO_RELAXATION`), sdp_rank_ratio, sdp_ms, sdp_point_kw (the losses of the
    relaxation's own point: `PhaseBound.point_kw`), contraction (`unique_point`'s factor,
    NaN where not computed) and optimality_gap (the relative gap to the bound, NaN where
    either is missing). Unbounded: no lower bound."""
    begin = now()
    net = scenario.net
    assert isinstance(net, PhaseNetwork)
    load_p, load_q = scenario.element_loads()
    if curtail and scenario.q_limit_mvar is not None:  # its capability is a function of the power it delivers
        raise ValueError("the AC OPF that may curtail takes no fixed reactive limit (q_limit_mvar)")
    limit = scenario.usable_q_mvar(check_reserve(k))  # "Q at night" where the scenario says
    offsets = capability_offsets(scenario, k, 1.0) if curtail else None
    opt = optimum(
        net,
        load_p,
        load_q,
        scenario.der_p_mw,
        k,
        q_limit_mvar=limit,
        fallback=fallback,
        slack_export=slack_export,
        curtail_offsets=offsets,
    )
    answered = (opt.status == OK) | (opt.status == FALLBACK_COLD)
    source = np.where(opt.status == FALLBACK_COLD, FROM_COLD, np.where(answered, FROM_SOLVER, FROM_NO_ACTION))
    source = np.where(opt.solver_status == NO_Q_TO_GIVE, np.where(opt.status == OK, FROM_SOLVER, FROM_NO_ACTION), source)
    lo, hi = net.band
    flow = opt.flow
    with np.errstate(invalid="ignore"):
        feasible = flow.converged & (flow.vm.min(axis=1) >= lo - BAND_TOL) & (flow.vm.max(axis=1) <= hi + BAND_TOL)
    n = scenario.n_snapshots
    certified_by, bounds = np.full(n, "", dtype=object), dict[str, np.ndarray]()
    if bounded and not curtail:
        certified_by, bounds = step_bounds(net, load_p, load_q, scenario.der_p_mw, limit, k, opt, feasible)
    rows = [
        {
            "objective_kw": float(opt.objective_kw[i]),
            "solver_status": str(opt.solver_status[i]),
            "fallback": str(source[i]),
            "certified_by": str(certified_by[i]),
            "solve_ms": float(opt.solve_ms[i]),
            "iterations": int(opt.iterations[i]),
            "warm_start": bool(opt.warm[i]),
        }
        for i in range(n)
    ]
    record, extra = solver_record(model, rows)
    full: dict[str, object] = {**extra, **bounds, "ac_feasible": feasible, "slack_export": bool(slack_export)}
    lower = np.where(feasible, bounds["relaxation_bound_kw"], np.nan) if bounds else None
    return StrategyResult.from_setpoints(
        name or model.name,
        k,
        scenario,
        opt.q_mvar,
        elapsed_ms(begin),
        power_flows=1,  # the no-action flow every snapshot starts from (the confirmations are the solves')
        pf=flow,
        status=opt.status,
        solver=record,
        extra=full,
        p_mw=opt.p_mw,
        lower_bound_kw=lower,
    )


def bound_sample(n: int) -> np.ndarray:
    """The steps `run_phase` bounds among n (`BOUND_SAMPLE`), ascending."""
    if n <= BOUND_SAMPLE:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, BOUND_SAMPLE).round().astype(int))


def step_bounds(
    net: PhaseNetwork,
    load_p: np.ndarray,
    load_q: np.ndarray,
    der_p: np.ndarray,
    limit: np.ndarray,
    k: float,
    opt: PhaseOptimum,
    feasible: np.ndarray,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(certified_by, per-step arrays) for `run_phase` on S snapshots (loads (S, n_load),
    DER P and usable |Q| (S, n_der)): at every step without a decision (no usable Q) whose
    optimum is the power flow's point, the proof that the point is the only feasible one
    (`sole_points`) — its losses are then the bound (status `UNIQUE`, certified_by
    `CERTIFIED_BY_UNIQUE`); the relaxation on `bound_sample`'s other steps, certified
    (`CERTIFIED_BY_SDP`) where the reported point meets the band (`feasible`) and its
    losses are within CERTIFY_RTOL of the bound (`certify`); arrays relaxation_bound_kw,
    sdp_status, sdp_rank_ratio, sdp_ms, sdp_point_kw, contraction, optimality_gap (S,) as
    `run_phase` says."""
    n = len(load_p)
    status = np.full(n, NOT_SAMPLED, dtype=object)
    unique, factor = sole_points(net, load_p, load_q, der_p, limit, opt)
    try:
        model_for("relaxation", net)
    except NetworkError:
        status[:] = NO_RELAXATION
        rows = np.zeros(0, dtype=int)
    else:
        rows = bound_sample(n)
        rows = rows[~unique[rows]]
    nan, no = np.full(n, np.nan), np.zeros(n, dtype=bool)
    relaxed = PhaseBound(nan, nan.copy(), no, no.copy(), status, np.zeros(n), nan.copy(), 0.0)
    if rows.size:
        part = bound(net, load_p[rows], load_q[rows], der_p[rows], k, q_limit_mvar=limit[rows])
        for f in fields(PhaseBound):
            if f.name != "compile_ms":
                getattr(relaxed, f.name)[rows] = getattr(part, f.name)
    relaxed.bound_kw[unique] = relaxed.point_kw[unique] = opt.losses_kw[unique]
    relaxed.status[unique] = UNIQUE
    certified, gap = certify(opt, relaxed)
    certified &= feasible
    certified_by = np.where(certified, np.where(unique, CERTIFIED_BY_UNIQUE, CERTIFIED_BY_SDP), "").astype(object)
    return certified_by, {
        "relaxation_bound_kw": relaxed.bound_kw,
        "sdp_status": relaxed.status,
        "sdp_rank_ratio": relaxed.rank_ratio,
        "sdp_ms": relaxed.solve_ms,
        "sdp_point_kw": relaxed.point_kw,
        "contraction": factor,
        "optimality_gap": np.where(feasible, gap, np.nan),
    }


def sole_points(
    net: PhaseNetwork, load_p: np.ndarray, load_q: np.ndarray, der_p: np.ndarray, limit: np.ndarray, opt: PhaseOptimum
) -> tuple[np.ndarray, np.ndarray]:
    """(unique, contraction) per snapshot: at the steps where no DER has usable Q and the
    optimum is the power flow's point (`NO_Q_TO_GIVE`, status ok), `unique_point` on the
    feeder at the taps that point holds (`tap_groups`), the region's rows widened by
    BAND_TOL — unique where that point is the only one the OPF's constraints admit, so
    its losses are the optimum's value; elsewhere False and NaN."""
    n = len(load_p)
    unique, factor = np.zeros(n, dtype=bool), np.full(n, np.nan)
    sole = np.flatnonzero(~(limit > 0).any(axis=1) & (opt.solver_status == NO_Q_TO_GIVE) & (opt.status == OK))
    if not sole.size:
        return unique, factor
    zero_q = np.zeros((sole.size, len(net.ders)))
    no_action = solve_phase_flow(net, load_p[sole], load_q[sole], der_p[sole])
    for held, at in tap_groups(net, no_action):
        rows = sole[at]
        flow = solve_phase_flow(held, load_p[rows], load_q[rows], der_p[rows])
        unique[rows], factor[rows] = unique_point(held, flow, load_p[rows], load_q[rows], der_p[rows], zero_q[at], BAND_TOL)
    return unique, factor


def run_phase_batch(
    model: ModelSpec, scenario: Scenario, k: float, *, name: str = "", slack_export: bool = True
) -> StrategyResult:
    """An approximation (or any model with `solve(load P, load Q, DER P, usable |Q|)` per
    snapshot and `predict` of the monitored voltages: `models.lindist3flow`) on every
    snapshot of a three-phase `scenario`, its setpoints evaluated by the power flow: status
    "ok" where it solved, "infeasible" where its program is (then no action, Q = 0),
    "solver-failed" otherwise (also Q = 0). The solver record: objective_kw (the model's
    own estimate of the losses), solver_status, fallback, certified_by "" (an estimate
    certifies nothing), solve_ms, iterations; extra: vm_error_pu (the largest |predicted −
    power flow| monitored voltage at its setpoints, p.u.; NaN where it did not solve or the
    flow diverged), ac_feasible (the reported point meets the band), slack_export."""
    begin = now()
    net = scenario.net
    assert isinstance(net, PhaseNetwork)
    load_p, load_q = scenario.element_loads()
    limit = scenario.usable_q_mvar(check_reserve(k))
    der_p = scenario.der_p_mw
    approx = built(model, net, slack_export)
    n = scenario.n_snapshots
    solves = [approx.solve(load_p[i], load_q[i], der_p[i], limit[i]) for i in range(n)]
    q = np.array([s.q_mvar if s.optimal else np.zeros(len(net.ders)) for s in solves]).reshape(n, len(net.ders))
    flow = solve_phase_flow(net, load_p, load_q, der_p, q)
    status = np.array([OK if s.optimal else INFEASIBLE if s.infeasible else SOLVER_FAILED for s in solves], dtype=object)
    error = np.full(n, np.nan)
    for i in np.flatnonzero((status == OK) & flow.converged):
        error[i] = np.abs(approx.predict(load_p[i], load_q[i], der_p[i], q[i]) - flow.vm[i]).max(initial=0.0)
    rows = [
        {
            "objective_kw": float(s.objective_kw),
            "solver_status": s.status,
            "fallback": FROM_SOLVER if s.optimal else FROM_NO_ACTION,
            "certified_by": "",
            "solve_ms": float(s.solve_ms),
            "iterations": int(s.iterations),
            VM_ERROR: float(error[i]),
        }
        for i, s in enumerate(solves)
    ]
    record, extra = solver_record(model, rows)
    lo, hi = net.band
    with np.errstate(invalid="ignore"):
        feasible = flow.converged & (flow.vm.min(axis=1) >= lo - BAND_TOL) & (flow.vm.max(axis=1) <= hi + BAND_TOL)
    return StrategyResult.from_setpoints(
        name or model.name,
        k,
        scenario,
        q,
        elapsed_ms(begin),
        power_flows=1,  # its evaluation
        pf=flow,
        status=status,
        solver=record,
        extra={**extra, "ac_feasible": feasible, "slack_export": bool(slack_export)},
    )


def _setpoints(solve, der_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A solve's (Q, P) MVAr/MW (n_der,) each: P the power each DER has, or where the model
    may curtail (`q_pu` holds Q, then P) the solve's, at the power it has where it curtails
    less than CURTAIL_SNAP_MW (the interior point stops that short of an active bound)."""
    n_der = der_p.size
    if solve.q_pu.size == n_der:
        return solve.q_pu, der_p
    p = solve.q_pu[n_der:]
    return solve.q_pu[:n_der], np.where(der_p - p < CURTAIL_SNAP_MW, der_p, p)


def _flow_start(net: PhaseNetwork, exact: ThreePhaseAc, solve: IpoptSolve, snapshot: tuple[np.ndarray, ...]) -> np.ndarray | None:
    """The NLP point of the power flow at `solve`'s setpoints (Q, P: `_setpoints`) on
    `snapshot` (load P, load Q, DER P), None where they are not finite or it diverges: a
    start that meets the network's equations where IPOPT's own iterate may not (ieee13's
    near-ideal regulators: an attempt that ran out of iterations far off them)."""
    load_p, load_q, der_p = snapshot
    q, p = _setpoints(solve, der_p)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        return None
    flow = solve_phase_flow(net, load_p[None], load_q[None], p[None], q[None])
    return exact.initial(flow.v[0], p, q) if flow.converged[0] else None


def _accepted(
    net: PhaseNetwork,
    solve,
    point: tuple[np.ndarray, np.ndarray],
    load_p: np.ndarray,
    load_q: np.ndarray,
    der_p: np.ndarray,
    slack_export: bool = True,
) -> bool:
    """IPOPT converged, and the power flow at the solve's setpoints `point` (Q, P:
    `_setpoints`) converges, meets the band (and, where the source may not take power
    back, draws power from it) and gives the model's cost — losses, plus the power
    curtailed — within CONFIRM_RTOL."""
    q, p = point
    if not solve.success or not np.isfinite(solve.objective_kw) or not np.all(np.isfinite(q)) or not np.all(np.isfinite(p)):
        return False
    flow = solve_phase_flow(net, load_p[None], load_q[None], p[None], q[None])
    if not flow.converged[0]:
        return False
    lo, hi = net.band
    within = lo - BAND_TOL <= flow.vm[0].min() and flow.vm[0].max() <= hi + BAND_TOL
    if not slack_export and flow.source_kva[0].real < -BAND_TOL:
        return False
    cost = flow.losses_kw[0] + 1e3 * float(np.sum(der_p - p))
    return bool(within and abs(cost - solve.objective_kw) <= CONFIRM_RTOL * abs(cost))


@dataclass(frozen=True, eq=False)
class PhaseBound:
    """The relaxation on S snapshots. Arrays (S,): `bound_kw` (NaN unless solved),
    `rank_ratio` (the largest second-to-first eigenvalue ratio over its PSD blocks),
    `rank_one` (every block rank one: `rank_ratio` ≤ the model's threshold), `infeasible`
    (the solver certified the relaxation, hence the OPF, infeasible), `status` (the
    solver's), `solve_ms` (per step), `point_kw` the losses of the relaxation's own point
    (the power flow at its DER Q, at the same taps; NaN unless solved and converged);
    `compile_ms` the model's build plus first solve (cvxpy compiles there) less that
    solve's own time (about 0 where this thread had built the model for this feeder
    already: it is kept, `model.built`)."""

    bound_kw: np.ndarray
    rank_ratio: np.ndarray
    rank_one: np.ndarray
    infeasible: np.ndarray
    status: np.ndarray
    solve_ms: np.ndarray
    point_kw: np.ndarray
    compile_ms: float


def bound(
    net: PhaseNetwork,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    k: float = 0.0,
    *,
    q_limit_mvar: np.ndarray | None = None,
) -> PhaseBound:
    """The relaxation's bound on S snapshots (arguments as `optimum`, `q_limit_mvar` the
    usable |Q| where the caller has it); NetworkError where no relaxation serves the feeder
    (meshed). Checked before any work: k, the model, then shapes and finite values (the
    power flow's checks, on the first snapshot)."""
    import time

    check_reserve(k)
    load_models()
    spec = model_for("relaxation", net)
    no_action = solve_phase_flow(net, load_p_mw, load_q_mvar, der_p_mw)  # checks shapes and values first
    load_p, load_q = (np.asarray(x, dtype=float).reshape(-1, net.n_load) for x in (load_p_mw, load_q_mvar))
    der_p = np.asarray(der_p_mw, dtype=float).reshape(len(load_p), len(net.ders))
    limit = q_limits(net, der_p, k) if q_limit_mvar is None else np.asarray(q_limit_mvar, dtype=float).reshape(der_p.shape)
    groups = tap_groups(net, no_action)
    if groups[0][0] is not net:  # under tap control: each snapshot at its no-action taps, held
        parts = [
            (rows, bound(held, load_p[rows], load_q[rows], der_p[rows], k, q_limit_mvar=limit[rows])) for held, rows in groups
        ]
        compile_ms = sum(part.compile_ms for _, part in parts)
        return PhaseBound(**_stitched(PhaseBound, len(load_p), parts, skip=("compile_ms",)), compile_ms=compile_ms)
    start = time.perf_counter()
    model = built(spec, net, True)
    solves = []
    for i in range(len(load_p)):
        solves.append(model.solve(load_p[i], load_q[i], der_p[i], limit[i]))
        if i == 0:
            compile_ms = (time.perf_counter() - start) * 1e3 - solves[0].solve_ms
    if not solves:
        compile_ms = (time.perf_counter() - start) * 1e3

    def field(name: str, dtype: type) -> np.ndarray:
        return np.array([getattr(s, name) for s in solves], dtype=dtype)

    q = np.array([s.q_mvar for s in solves], dtype=float).reshape(len(solves), len(net.ders))
    point = np.full(len(solves), np.nan)
    solved = np.flatnonzero(np.isfinite(q).all(axis=1))
    if solved.size:
        flow = solve_phase_flow(net, load_p[solved], load_q[solved], der_p[solved], der_q_mvar=q[solved])
        point[solved] = np.where(flow.converged, flow.losses_kw, np.nan)
    return PhaseBound(
        field("bound_kw", float),
        field("rank_ratio", float),
        field("rank_one", bool),
        field("infeasible", bool),
        field("status", object),
        field("solve_ms", float),
        point,
        compile_ms,
    )


def certify(opt: PhaseOptimum, relaxed: PhaseBound) -> tuple[np.ndarray, np.ndarray]:
    """(certified, gap) per snapshot: the gap (optimum's losses − bound) / optimum's losses
    where both exist (NaN elsewhere); certified where that gap is within CERTIFY_RTOL and
    the bound is attained: the relaxation's own point (`PhaseBound.point_kw`, the power
    flow at its DER Q) has losses within CERTIFY_RTOL of it. The second test guards against
    the conic solver's accuracy: on eulv a solve reported "optimal" sat 1.2e-5 above the
    AC optimum, its own point below its value — a value no operating point attains is no
    certificate, however close to the optimum it lands."""
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = (opt.losses_kw - relaxed.bound_kw) / np.abs(opt.losses_kw)
        attained = np.abs(relaxed.point_kw - relaxed.bound_kw) <= CERTIFY_RTOL * np.abs(relaxed.point_kw)
    return np.isfinite(gap) & (np.abs(gap) <= CERTIFY_RTOL) & attained, gap


def tap_groups(net: PhaseNetwork, no_action: PhaseFlowResult) -> list[tuple[PhaseNetwork, np.ndarray]]:
    """The snapshots of `no_action` (the power flow on `net` with Q = 0) grouped by the
    regulators' taps the OPF and its relaxation hold: on a feeder under tap control
    (`?taps=control`) each snapshot's taps where the no-action flow's controller settled
    them — per group the feeder at those taps, held (`powerflow.multiphase.tapped`, one
    object per taps: what is built for it serves the group), with `net`'s band — and the
    snapshots' indices, ascending; otherwise one group, `net` itself at its elements' taps."""
    if no_action.tap_positions is None:
        return [(net, np.arange(no_action.n_snapshots))]
    taps, which = np.unique(no_action.tap_positions, axis=0, return_inverse=True)
    out = []
    for group, positions in enumerate(taps):
        held = tapped(net.origin, tuple(int(t) for t in positions))
        out.append((held if held.band == net.band else held.with_band(*net.band), np.flatnonzero(which.reshape(-1) == group)))
    return out


def _stitched(kind: type, n: int, parts: Sequence[tuple[np.ndarray, Any]], skip: tuple[str, ...]) -> dict[str, Any]:
    """The array fields (first axis: snapshots) of the records `parts` ((rows, record)
    each, of dataclass `kind`) placed at their rows among n; a field None in the records
    stays None; the fields `skip` are left to the caller."""
    out: dict[str, Any] = {}
    for f in fields(kind):
        if f.name in skip:
            continue
        first = getattr(parts[0][1], f.name)
        if first is None:
            out[f.name] = None
            continue
        whole = np.empty((n, *first.shape[1:]), dtype=first.dtype)
        for rows, part in parts:
            whole[rows] = getattr(part, f.name)
        out[f.name] = whole
    return out
