"""The run's tables (columns: `opfbench.schema`, docs/CONTRACTS.md): per-step rows of one
strategy result, the optional detail tables (per-DER Q, per-bus V), the frontier's steps,
and the summaries, built from per-task partial sums so that a year never has to sit in
memory at once.

Every configuration's step is compared with the frontier (`formulations.frontier`) at the
smallest grid ε that covers its own excursion beyond the voltage band, and at the capability
its setpoints used (Algorithm 3's, or k = 0, where they used the reserve; none where they
exceed the DER's capability, which no inverter delivers): its cost (losses
plus curtailed power) against the optimum as compliant as it — the **gap at equal
compliance** (≥ 0 where the optimum is global and the point is in the OPF's set) — and,
over the period, the **share at equal compliance**: the reduction of the cost below no
action's losses over the reduction that optimum makes, (E_na − C)/(E_na − F), ≤ 100 %.
The plain, loss-only share (E_na − E)/(E_na − E_acopf) is kept beside it (`share_pct`):
it compares a rule with an optimum that holds the band whatever the rule does.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.errors import InputError
from opfbench.formulations.frontier import CAPABILITY, FORECAST, Frontier
from opfbench.multiphase import PhaseNetwork
from opfbench.registry.catalog import configuration, describe
from opfbench.registry.references import BASELINE, REFERENCE_OPTIMUM
from opfbench.result import NOT_SETTLED, OK, PF_DIVERGED, RULE_NON_FINITE, Reference, StrategyResult
from opfbench.schema import (
    BUS_V,
    DER_Q,
    FRONTIER,
    FRONTIER_SUMMARY,
    KEYS,
    STEPS,
    SUMMARY,
    TASK_FRONTIER_SUMMARY,
    TASK_SUMMARY,
    StepContext,
)
from opfbench.study.config import DETAIL_TABLES

DETAIL_COLUMNS = {"der_q": DER_Q.names, "bus_v": BUS_V.names}
FRONTIER_KEYS = ["case", "k", "night_mode", "curtail"]
FRONTIER_COLUMNS = FRONTIER.names
VIOLATION_PU = 1e-6  # a step violates the voltage limits beyond this
VUF_LIMIT_PCT = 2.0  # EN 50160's limit of the voltage unbalance factor, %
EXCURSION_MVAR = 1e-9  # a step's setpoint exceeds the physical capability beyond this
BELOW_KW = 1e-4  # a cost this far below its frontier point counts as below it (solver tolerances)
SHARE_MIN_KWH = 1e-6  # a reduction below this defines no share
RESERVE_USED = (FORECAST, CAPABILITY)  # the frontier limits of a step whose setpoints used the reserve


def extra_columns(labels: tuple[str, ...]) -> tuple[str, ...]:
    """The extra per-step columns the strategies of `labels` declare (`StrategySpec.columns`),
    each once, in the order they first appear; InputError naming the strategy that
    declares one of the table's own columns (before any work)."""
    for label in labels:
        spec = configuration(label).spec
        clash = [c for c in spec.columns if c in STEPS.names]
        if clash:
            raise InputError(
                f"strategy {spec.name} ({spec.source}) declares the extra column {clash[0]!r}, one of the steps table's "
                f"own ({', '.join(STEPS.names)}): give its column another name"
            )
    return tuple(dict.fromkeys(c for label in labels for c in configuration(label).spec.columns))


def step_columns(extra: tuple[str, ...] = ()) -> list[str]:
    """The per-step table's columns: `schema.STEPS`'s, then the strategies' extra ones."""
    return [*STEPS.names, *extra]


Columns = dict[str, np.ndarray | str | float | int | bool]  # name → the part's rows, or one value for all


def step_rows(
    case: str,
    night_mode: str,
    forecast: str,
    time: pd.DatetimeIndex,
    step_h: float,
    night: np.ndarray,
    res: StrategyResult,
    extra_columns: tuple[str, ...] = (),
    reference: Reference | None = None,
) -> Columns:
    """The columns of one row per step of `res` (`schema.STEPS`, each computed by its
    declaration), for `stack`; the `extra_columns` from `res.extra` (NaN where this
    strategy has none); the frontier point at the step's compliance
    (`formulations.frontier.reference`; NaN without one)."""
    context = StepContext(case, night_mode, forecast, time.asi8, step_h, night, res, reference)
    nan = np.full(res.n_snapshots, np.nan)
    return STEPS.compute(context) | {name: np.asarray(res.extra.get(name, nan), dtype=float) for name in extra_columns}


def frontier_rows(case: str, k: float, night_mode: str, time: pd.DatetimeIndex, step_h: float, front: Frontier) -> Columns:
    """The frontier's rows (see the contract: one per step of `time` — its steps — and grid
    ε), for `stack`."""
    n, m = front.cost_kw.shape
    return {
        "case": case,
        "k": float(k),
        "night_mode": night_mode,
        "curtail": bool(front.curtail),
        "time": np.repeat(time.asi8, m),
        "step_h": float(step_h),
        "eps_pu": np.tile(front.eps, n),
        "cost_kw": front.cost_kw.reshape(-1),
        "bound_kw": front.bound_kw.reshape(-1),
        "excursion_pu": front.excursion_pu.reshape(-1),
        "status": front.status.reshape(-1).astype(str),
        "solved": front.solved.reshape(-1),
    }


def detail_rows(
    case: str,
    night_mode: str,
    forecast: str,
    time: pd.DatetimeIndex,
    res: StrategyResult,
    tables: tuple[str, ...] = DETAIL_TABLES,
) -> dict[str, Columns]:
    """The columns of the long tables named in `tables`, for `stack`: "der_q" per-DER
    setpoints (DER name, bus id, kind, q_mvar, curtailed_mw), "bus_v" per-bus |V| (p.u.)."""
    net = res.net
    n = res.n_snapshots
    label: Columns = {"case": case, "strategy": res.strategy, "k": float(res.k), "night_mode": night_mode, "forecast": forecast}

    def der_q() -> Columns:
        n_der = len(net.ders)
        curtailed = np.zeros(n * n_der) if res.curtailed_mw is None else res.curtailed_mw.reshape(-1)
        return label | {
            "time": np.repeat(time.asi8, n_der),
            "der": np.tile(np.asarray(net.der_names, dtype=str), n),
            "bus": np.tile(net.der_bus if isinstance(net, PhaseNetwork) else net.bus_ids[net.der_bus], n).astype(np.int64),
            "kind": np.tile(np.asarray(net.der_kinds, dtype=str), n),
            "q_mvar": res.q_mvar.reshape(-1),
            "curtailed_mw": curtailed,
        }

    def bus_v() -> Columns:
        return label | {
            "time": np.repeat(time.asi8, net.n_bus),
            "bus": np.tile(net.bus_ids, n).astype(np.int64),
            "v_pu": res.vm.reshape(-1),
        }

    build = {"der_q": der_q, "bus_v": bus_v}
    return {name: build[name]() for name in tables}


def stack(parts: list[Columns], columns: list[str], tz) -> pd.DataFrame:
    """One frame of `columns` from parts (`step_rows`, `detail_rows`), each as many rows
    as its arrays are long; one value for a part is repeated. Text is categorical (one
    value, or a few, repeated on every row: many times faster to build and to hand
    between processes; the files hold plain text, `store._arrow`); "time" (UTC ns) gets
    the zone `tz`."""
    rows = [max(np.shape(v)[0] for v in part.values() if np.ndim(v)) for part in parts]
    data = {}
    for name in columns:
        values = [part[name] for part in parts]
        if values and all(isinstance(v, str) for v in values):
            categories = list(dict.fromkeys(values))
            codes = np.repeat(np.array([categories.index(v) for v in values], dtype=np.int32), rows)
            data[name] = pd.Categorical.from_codes(codes, categories)
        elif name == "time":
            times = np.concatenate([np.asarray(v) for v in values]) if values else np.zeros(0, dtype=np.int64)
            data[name] = pd.DatetimeIndex(times.view("datetime64[ns]")).tz_localize("UTC").tz_convert(tz)
        else:
            arrays = [np.full(r, v) if np.ndim(v) == 0 else np.asarray(v) for v, r in zip(values, rows, strict=True)]
            column = np.concatenate(arrays) if arrays else np.zeros(0)
            is_text = column.dtype.kind in "UO"
            data[name] = pd.Categorical(column) if is_text else column
    return pd.DataFrame(data, columns=columns)


def partial_summary(steps: pd.DataFrame) -> pd.DataFrame:
    """Sums, counts and extremes per configuration of one task's rows (combined by
    `summarize`)."""
    measured = steps.losses_kw.notna()  # a converged power flow: the step has a loss and voltage figure
    cost = steps.losses_kw + steps.curtailed_kw
    on = (cost < steps.frontier_kw) & (cost >= steps.frontier_kw - BELOW_KW)  # on its frontier point, within tolerances
    s = steps.assign(
        energy=steps.losses_kw * steps.step_h,
        curtailed=steps.curtailed_kw * steps.step_h,
        front=steps.frontier_kw.where(~on, cost) * steps.step_h,
        front_missing=steps.frontier_kw.isna().astype(np.int64),
        front_bound=steps.frontier_bound_kw * steps.step_h,
        front_bound_missing=steps.frontier_bound_kw.isna().astype(np.int64),
        below=(cost < steps.frontier_kw - BELOW_KW).astype(np.int64),
        reserve_used=steps.frontier_limit.isin(RESERVE_USED).astype(np.int64),
        measured=measured.astype(np.int64),
        measured_h=steps.step_h.where(measured, 0.0),
        lb_energy=steps.lower_bound_kw * steps.step_h,
        lb_missing=steps.lower_bound_kw.isna().astype(np.int64),
        not_ok=(steps.status != OK).astype(np.int64),
        not_settled=(steps.status == NOT_SETTLED).astype(np.int64),
        pf_diverged=(steps.status == PF_DIVERGED).astype(np.int64),
        non_finite=(steps.status == RULE_NON_FINITE).astype(np.int64),
        vv=(steps.voltage_violation_pu > VIOLATION_PU).astype(np.int64),
        vv_h=steps.step_h.where(steps.voltage_violation_pu > VIOLATION_PU, 0.0),
        vuf_h=steps.step_h.where(steps.max_vuf_pct > VUF_LIMIT_PCT, 0.0),
        exc=(steps.excursion_mvar > EXCURSION_MVAR).astype(np.int64),
        solver_known=steps.solver_ms.notna().astype(np.int64),
        certified=(steps.certified_by != "").astype(np.int64),
    )
    g = s.groupby(KEYS, sort=False, observed=True)
    sums = pd.DataFrame(
        {
            "steps": g.size(),
            "hours": g.step_h.sum(),
            "pf_converged_steps": g.measured.sum(),
            "measured_hours": g.measured_h.sum(),
            "energy_kwh": g.energy.sum(),
            "curtailed_kwh": g.curtailed.sum(),
            "frontier_kwh": g.front.sum(),
            "frontier_missing": g.front_missing.sum(),
            "frontier_bound_kwh": g.front_bound.sum(),
            "frontier_bound_missing": g.front_bound_missing.sum(),
            "below_frontier_steps": g.below.sum(),
            "frontier_curtails": g.frontier_curtails.max(),
            "reserve_used_steps": g.reserve_used.sum(),
            "not_ok_steps": g.not_ok.sum(),
            "not_settled_steps": g.not_settled.sum(),
            "pf_diverged_steps": g.pf_diverged.sum(),
            "rule_non_finite_steps": g.non_finite.sum(),
            "voltage_violation_steps": g.vv.sum(),
            "voltage_violation_h": g.vv_h.sum(),
            "max_violation_pu": g.voltage_violation_pu.max(),
            "vmin_pu": g.vmin_pu.min(),
            "vmax_pu": g.vmax_pu.max(),
            "max_vuf_pct": g.max_vuf_pct.max(),
            "vuf_h": g.vuf_h.sum(),
            "max_excursion_mvar": g.excursion_mvar.max(),
            "excursion_steps": g.exc.sum(),
            "lower_bound_kwh": g.lb_energy.sum(),
            "lb_missing": g.lb_missing.sum(),
            "wall_s": g.wall_ms.sum() / 1e3,
            "solver_s": g.solver_ms.sum() / 1e3,
            "solver_known": g.solver_known.sum(),
            "certified": g.certified.sum(),
        }
    )
    return sums[list(PARTIAL_COLUMNS)].reset_index()


PARTIAL_COLUMNS = tuple(TASK_SUMMARY.names[len(KEYS) :])
"""The columns of a task's partial sums (`partial_summary`) besides KEYS."""
EXTREMES = {
    "vmin_pu": "min",
    "vmax_pu": "max",
    "max_vuf_pct": "max",
    "max_excursion_mvar": "max",
    "max_violation_pu": "max",
    "frontier_curtails": "max",
}
"""The partial sums' extremes (combined by `summarize` with these; the others are summed)."""


def summarize(partials: list[pd.DataFrame], order: list[tuple]) -> pd.DataFrame:
    """The summary (one row per configuration, in `order` of KEYS tuples) from
    `partial_summary` frames. A step whose power flow did not converge (pf-diverged) or
    whose rule gave no finite target (rule-non-finite) has no loss or voltage figure: each
    status is counted under its own name (pf_diverged_steps, rule_non_finite_steps),
    pf_converged_steps counts the steps with a figure — the steps avg_loss_kw, vmin_pu,
    vmax_pu and voltage_violation_steps are over; energy_kwh (the period's) is NaN unless
    every step has a figure, and so are the
    savings and gaps built on it. no_action_kwh: the baseline's (`registry.BASELINE`)
    energy for the same case, k and night mode with forecast off; lower_bound_kwh: the
    certified bound over the same steps from the strategy at its default options with the
    lowest `bound_rank` (the SOCP, slack may export, else the AC OPF's record of it), NaN
    unless every step has one. curtailed_kwh: the active energy the DER had and did not
    deliver (a rule's Volt-Watt or reactive priority); cost_kwh = energy_kwh + curtailed_kwh.
    voltage_violation_min: minutes of steps outside the case's voltage limits,
    max_violation_pu the worst excursion beyond them; max_vuf_pct the worst voltage
    unbalance factor (three-phase feeders), vuf_min the minutes above VUF_LIMIT_PCT; not_settled_steps: steps where a
    closed-loop rule did not settle. At equal compliance (module docstring): frontier_kwh
    the frontier's optimum at each step's compliance and the capability it used (NaN unless
    every step has one; frontier_missing_steps count those without — no optimum at their ε,
    or setpoints beyond the DER's capability —, reserve_used_steps those whose setpoints used
    the reserve, compared at the capability they used), frontier_bound_kwh its certified bound,
    gap_eq_kwh = cost_kwh − frontier_kwh (a step's cost within BELOW_KW under its frontier
    point counts as on it: the solvers' tolerances), gap_eq_pct of frontier_kwh, share_eq_pct =
    100·(no_action_kwh − cost_kwh)/(no_action_kwh − frontier_kwh) where that reduction
    exceeds SHARE_MIN_KWH, below_frontier_steps the steps whose cost lies more than
    BELOW_KW under their frontier point, frontier_curtails whether that frontier is the
    optimum's that may curtail (the reference of the configurations that curtail);
    share_pct the plain loss-only share,
    100·(no_action_kwh − energy_kwh)/(no_action_kwh − the reference optimum's energy)."""
    p = pd.concat(partials, ignore_index=True)
    g = p.groupby(KEYS, sort=False, observed=True)
    out = g[[c for c in PARTIAL_COLUMNS if c not in EXTREMES]].sum()
    for column, how in EXTREMES.items():
        out = out.join(g[column].agg(how))
    out = out.reindex(pd.MultiIndex.from_tuples(order, names=KEYS)).reset_index()
    out["avg_loss_kw"] = (out.energy_kwh / out.measured_hours).where(out.pf_converged_steps > 0)
    out["energy_kwh"] = out.energy_kwh.where(out.pf_converged_steps == out.steps)  # a period's energy needs every step's
    out["solver_s"] = out.solver_s.where(out.solver_known > 0)
    out["certified_share"] = out.certified / out.steps
    out["voltage_violation_min"] = 60.0 * out.pop("voltage_violation_h")
    out["vuf_min"] = 60.0 * out.pop("vuf_h")
    base = out[(out.strategy == BASELINE) & (out.forecast == "off")].set_index(["case", "k", "night_mode"]).energy_kwh
    out["no_action_kwh"] = pd.MultiIndex.from_frame(out[["case", "k", "night_mode"]]).map(base.to_dict().get).astype(float)
    out["savings_pct"] = 100 * (1 - out.energy_kwh / out.no_action_kwh)
    bound = out.assign(rank=out.strategy.map({label: _bound_rank(label) for label in out.strategy.unique()}))
    bound = bound[bound["rank"].notna() & (bound.lb_missing == 0)]
    bound = (
        bound.sort_values("rank", kind="stable")
        .drop_duplicates(["case", "k", "night_mode"])
        .set_index(["case", "k", "night_mode"])
    )
    out["lower_bound_kwh"] = (
        pd.MultiIndex.from_frame(out[["case", "k", "night_mode"]]).map(bound.lower_bound_kwh.to_dict().get).astype(float)
    )
    out["gap_kwh"] = out.energy_kwh - out.lower_bound_kwh
    out["gap_pct"] = 100 * out.gap_kwh / out.lower_bound_kwh
    out["cost_kwh"] = out.energy_kwh + out.curtailed_kwh
    out["frontier_curtails"] = out.frontier_curtails.astype(bool)
    out["frontier_missing_steps"] = out.pop("frontier_missing")
    out["frontier_kwh"] = out.frontier_kwh.where(out.frontier_missing_steps == 0)
    out["frontier_bound_kwh"] = out.frontier_bound_kwh.where(out.pop("frontier_bound_missing") == 0)
    out["gap_eq_kwh"] = out.cost_kwh - out.frontier_kwh
    out["gap_eq_pct"] = 100 * out.gap_eq_kwh / out.frontier_kwh
    reduction = out.no_action_kwh - out.frontier_kwh
    out["share_eq_pct"] = (100 * (out.no_action_kwh - out.cost_kwh) / reduction).where(reduction > SHARE_MIN_KWH)
    optimum = out[(out.strategy == REFERENCE_OPTIMUM) & (out.forecast == "off")].set_index(["case", "k", "night_mode"]).energy_kwh
    e_opt = pd.MultiIndex.from_frame(out[["case", "k", "night_mode"]]).map(optimum.to_dict().get).astype(float)
    plain = out.no_action_kwh - e_opt
    out["share_pct"] = (100 * (out.no_action_kwh - out.energy_kwh) / plain).where(plain > SHARE_MIN_KWH)
    integers = {c.name: np.int64 for c in SUMMARY if c.dtype == "integer"}
    return out[SUMMARY.names].astype(integers)


def _bound_rank(label: str) -> float:
    """The `bound_rank` of a label that is a strategy at its default options (NaN: none)."""
    spec = describe(label)
    return float(spec.bound_rank) if spec is not None and spec.bound_rank is not None and label == spec.name else np.nan


def partial_frontier(front: pd.DataFrame) -> pd.DataFrame:
    """Sums per (case, k, night mode, ε) of one task's frontier rows (combined by
    `summarize_frontier`)."""
    s = front.assign(
        energy=front.cost_kw * front.step_h,
        missing=front.cost_kw.isna().astype(np.int64),
        bound=front.bound_kw * front.step_h,
        bound_missing=front.bound_kw.isna().astype(np.int64),
        outside_h=front.step_h.where(front.excursion_pu > VIOLATION_PU, 0.0),
        solved=front.solved.astype(np.int64),
    )
    g = s.groupby([*FRONTIER_KEYS, "eps_pu"], sort=False, observed=True)
    sums = pd.DataFrame(
        {
            "steps": g.size(),
            "energy_kwh": g.energy.sum(),
            "missing": g.missing.sum(),
            "bound_kwh": g.bound.sum(),
            "bound_missing": g.bound_missing.sum(),
            "outside_h": g.outside_h.sum(),
            "max_excursion_pu": g.excursion_pu.max(),
            "solved": g.solved.sum(),
        }
    )
    return sums.reset_index()[TASK_FRONTIER_SUMMARY.names]


def summarize_frontier(partials: list[pd.DataFrame]) -> pd.DataFrame:
    """The frontier of each (case, k, night mode): per grid ε the optimum's energy over the
    period (NaN unless every step has an optimum at that ε; no_optimum_steps count those
    without: infeasible, or only a fallback point), its certified bound's, the minutes its
    optimum lies outside the (unwidened) band and its worst excursion there, and the steps
    solved at that ε (the others take the answer of an ε that covers them)."""
    if not partials:
        return pd.DataFrame(columns=FRONTIER_SUMMARY.names)
    p = pd.concat(partials, ignore_index=True)
    g = p.groupby([*FRONTIER_KEYS, "eps_pu"], sort=False)
    out = g[["steps", "energy_kwh", "missing", "bound_kwh", "bound_missing", "outside_h", "solved"]].sum()
    out = out.join(g["max_excursion_pu"].max()).reset_index()
    out["energy_kwh"] = out.energy_kwh.where(out.missing == 0)
    out["bound_kwh"] = out.bound_kwh.where(out.pop("bound_missing") == 0)
    out = out.rename(columns={"missing": "no_optimum_steps", "max_excursion_pu": "max_violation_pu", "solved": "solved_steps"})
    out["voltage_violation_min"] = 60.0 * out.pop("outside_h")
    integers = {c.name: np.int64 for c in FRONTIER_SUMMARY if c.dtype == "integer"}
    return out[FRONTIER_SUMMARY.names].astype(integers)
