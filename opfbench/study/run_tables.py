"""The run's tables (columns: `opfbench.schema`, docs/CONTRACTS.md): per-step rows of one
strategy result, the optional detail tables (per-DER Q, per-bus V), and the summary,
built from per-task partial sums so that a year never has to sit in memory at once.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from opfbench.registry.catalog import configuration, describe
from opfbench.registry.references import BASELINE
from opfbench.result import NOT_SETTLED, OK, PF_DIVERGED, RULE_NON_FINITE, StrategyResult
from opfbench.schema import BUS_V, DER_Q, KEYS, STEPS, SUMMARY, TASK_SUMMARY, StepContext
from opfbench.study.config import DETAIL_TABLES

DETAIL_COLUMNS = {"der_q": DER_Q.names, "bus_v": BUS_V.names}
VIOLATION_PU = 1e-6  # a step violates the voltage limits beyond this
EXCURSION_MVAR = 1e-9  # a step's setpoint exceeds the physical capability beyond this


def extra_columns(labels: tuple[str, ...]) -> tuple[str, ...]:
    """The extra per-step columns the strategies of `labels` declare (`StrategySpec.columns`),
    each once, in the order they first appear."""
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
) -> Columns:
    """The columns of one row per step of `res` (`schema.STEPS`, each computed by its
    declaration), for `stack`; the `extra_columns` from `res.extra` (NaN where this
    strategy has none)."""
    context = StepContext(case, night_mode, forecast, time.asi8, step_h, night, res)
    nan = np.full(res.n_snapshots, np.nan)
    return STEPS.compute(context) | {name: np.asarray(res.extra.get(name, nan), dtype=float) for name in extra_columns}


def detail_rows(
    case: str,
    night_mode: str,
    forecast: str,
    time: pd.DatetimeIndex,
    res: StrategyResult,
    tables: tuple[str, ...] = DETAIL_TABLES,
) -> dict[str, Columns]:
    """The columns of the long tables named in `tables`, for `stack`: "der_q" per-DER
    setpoints (DER name, bus id, kind, q_mvar), "bus_v" per-bus |V| (p.u.)."""
    net = res.net
    n = res.n_snapshots
    label: Columns = {"case": case, "strategy": res.strategy, "k": float(res.k), "night_mode": night_mode, "forecast": forecast}

    def der_q() -> Columns:
        n_der = len(net.ders)
        return label | {
            "time": np.repeat(time.asi8, n_der),
            "der": np.tile(np.asarray(net.der_names, dtype=str), n),
            "bus": np.tile(net.bus_ids[net.der_bus], n).astype(np.int64),
            "kind": np.tile(np.asarray(net.der_kinds, dtype=str), n),
            "q_mvar": res.q_mvar.reshape(-1),
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
        if all(isinstance(v, str) for v in values):
            categories = list(dict.fromkeys(values))
            codes = np.repeat(np.array([categories.index(v) for v in values], dtype=np.int32), rows)
            data[name] = pd.Categorical.from_codes(codes, categories)
        elif name == "time":
            times = np.concatenate([np.asarray(v) for v in values])
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
    s = steps.assign(
        energy=steps.losses_kw * steps.step_h,
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
            "not_ok_steps": g.not_ok.sum(),
            "not_settled_steps": g.not_settled.sum(),
            "pf_diverged_steps": g.pf_diverged.sum(),
            "rule_non_finite_steps": g.non_finite.sum(),
            "voltage_violation_steps": g.vv.sum(),
            "voltage_violation_h": g.vv_h.sum(),
            "max_violation_pu": g.voltage_violation_pu.max(),
            "vmin_pu": g.vmin_pu.min(),
            "vmax_pu": g.vmax_pu.max(),
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
EXTREMES = {"vmin_pu": "min", "vmax_pu": "max", "max_excursion_mvar": "max", "max_violation_pu": "max"}
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
    unless every step has one. voltage_violation_min: minutes of steps outside the case's
    voltage limits, max_violation_pu the worst excursion beyond them; not_settled_steps:
    steps where a closed-loop rule did not settle."""
    p = pd.concat(partials, ignore_index=True)
    g = p.groupby(KEYS, sort=False)
    out = g[[c for c in PARTIAL_COLUMNS if c not in EXTREMES]].sum()
    for column, how in EXTREMES.items():
        out = out.join(g[column].agg(how))
    out = out.reindex(pd.MultiIndex.from_tuples(order, names=KEYS)).reset_index()
    out["avg_loss_kw"] = (out.energy_kwh / out.measured_hours).where(out.pf_converged_steps > 0)
    out["energy_kwh"] = out.energy_kwh.where(out.pf_converged_steps == out.steps)  # a period's energy needs every step's
    out["solver_s"] = out.solver_s.where(out.solver_known > 0)
    out["certified_share"] = out.certified / out.steps
    out["voltage_violation_min"] = 60.0 * out.pop("voltage_violation_h")
    base = out[(out.strategy == BASELINE) & (out.forecast == "off")].set_index(["case", "k", "night_mode"]).energy_kwh
    out["no_action_kwh"] = pd.MultiIndex.from_frame(out[["case", "k", "night_mode"]]).map(base.to_dict().get).astype(float)
    out["savings_pct"] = 100 * (1 - out.energy_kwh / out.no_action_kwh)
    bound = out.assign(rank=out.strategy.map(_bound_rank))
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
    integers = {c.name: np.int64 for c in SUMMARY if c.dtype == "integer"}
    return out[SUMMARY.names].astype(integers)


def _bound_rank(label: str) -> float:
    """The `bound_rank` of a label that is a strategy at its default options (NaN: none)."""
    spec = describe(label)
    return float(spec.bound_rank) if spec is not None and spec.bound_rank is not None and label == spec.name else np.nan
