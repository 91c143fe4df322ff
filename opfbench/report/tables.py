"""The report's tables, derived from the run / forecast / fault files (pandas in, pandas out).

Conventions: energies kWh, losses kW, voltages p.u., times ms; savings % = 100·(1 −
E/E_no-action) with E_no-action the same case/k/night mode, forecast off (summary.csv's
`no_action_kwh`). Every table keeps the `case` column so several feeders stay apart.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.dynamics.recovery import KEYS as RECOVERY_KEYS
from opfbench.dynamics.recovery import recovery_table
from opfbench.registry.catalog import describe, rank
from opfbench.registry.references import BASELINE, PAPER_OPF, PAPER_RULES, REFERENCE_OPTIMUM
from opfbench.report import paper_figures as paper
from opfbench.result import (
    CERTIFIED_BY_IPOPT,
    CERTIFIED_BY_SDP,
    CERTIFIED_BY_SOCP,
    CERTIFIED_BY_UNIQUE,
    PF_DIVERGED,
    RULE_NON_FINITE,
    STATUSES,
)

CONFIG = ["case", "strategy", "k", "night_mode", "forecast"]
REFERENCE_NIGHT = "connected"
TOL_KWH = 1e-6  # energies closer than this count as equal
"""The night mode of the tables that fix one (the paper's main setting)."""
NO_FIGURE = {
    "pf_diverged_steps": (PF_DIVERGED, "the power flow did not converge"),
    "rule_non_finite_steps": (RULE_NON_FINITE, "the rule gave NaN or inf: no setpoint"),
}
"""summary.csv's counts of the steps without a loss or voltage figure, by status, and why."""
FIGURE_STEPS = ("pf_converged_steps", *NO_FIGURE)
"""summary.csv's counts of steps with a figure and without one, by status (a summary
written before they existed has none: every step there had a figure or none was counted)."""


def figure_steps(summary: pd.DataFrame) -> list[str]:
    """The `FIGURE_STEPS` columns `summary` has."""
    return [c for c in FIGURE_STEPS if c in summary.columns]


def without_figures(summary: pd.DataFrame) -> pd.DataFrame:
    """The configurations with steps that have no loss or voltage figure (any `NO_FIGURE` status)."""
    counts = [c for c in NO_FIGURE if c in summary.columns]
    if not counts:
        return summary.iloc[:0]
    return summary[(summary[counts] > 0).any(axis=1)]


def order(frame: pd.DataFrame) -> pd.DataFrame:
    """Rows in the registry's strategy order (a strategy's configurations by label, unknown
    strategies last), then case, k, night mode, forecast."""
    keys = [c for c in ("case", "strategy", "k", "night_mode", "forecast") if c in frame.columns]
    # each distinct label ranked once (a steps frame repeats every label on each of its rows)
    ranks = {label: rank(label) for label in frame["strategy"].unique()} if "strategy" in frame else {}
    out = frame.assign(_rank=frame["strategy"].map(ranks)) if "strategy" in frame else frame
    by = [c if c != "strategy" else "_rank" for c in keys]
    by = [*by[: by.index("_rank") + 1], "strategy", *by[by.index("_rank") + 1 :]] if "_rank" in by else by
    out = out.sort_values(by, kind="stable") if by else out
    return out.drop(columns="_rank", errors="ignore").reset_index(drop=True)


def losses(summary: pd.DataFrame, price_per_kwh: float) -> pd.DataFrame:
    """Per configuration: avg kW (over the steps with a converged power flow, counted
    beside it), kWh, savings % and money saved per day and per year (the run's savings
    scaled to 24 h and to 365 days) at `price_per_kwh`."""
    days = summary["hours"] / 24.0
    saved_per_day = (summary["no_action_kwh"] - summary["energy_kwh"]) / days
    out = summary[CONFIG + ["avg_loss_kw", *figure_steps(summary), "energy_kwh", "savings_pct"]].assign(
        saved_kwh_per_day=saved_per_day,
        money_per_day=saved_per_day * price_per_kwh,
        money_per_year=saved_per_day * price_per_kwh * 365.0,
    )
    return order(out)


def energy_pivot(summary: pd.DataFrame, night_mode: str = REFERENCE_NIGHT, value: str = "energy_kwh") -> pd.DataFrame:
    """`value` per (case, strategy, forecast) × k, one night mode."""
    sub = summary[summary["night_mode"] == night_mode]
    table = sub.pivot_table(index=["case", "strategy", "forecast"], columns="k", values=value, aggfunc="first")
    table.columns = [f"k={k:g}" for k in table.columns]
    return order(table.reset_index())


@dataclass(frozen=True)
class Kinds:
    """How a run folder's configurations are classified: the formulations, those of them
    whose point is not a certified AC optimum (a relaxation's or an approximation's), and
    the configurations that read a forecast — as the folder's manifest records them
    (`StrategySpec.record`), so a report built without a plugin classifies its rows right;
    a folder older than the record is classified by the registry, a name neither knows as
    a local rule that reads a forecast."""

    formulations: frozenset[str] = frozenset()
    inexact: frozenset[str] = frozenset()
    forecast_readers: frozenset[str] = frozenset()

    @classmethod
    def of(cls, labels: Iterable[str], recorded: dict | None = None) -> "Kinds":
        formulations, inexact, readers = set(), set(), set()
        for label in dict.fromkeys(map(str, labels)):
            record = (recorded or {}).get(label)
            if record is None:
                spec = describe(label)
                record = spec.record() if spec is not None else {"kind": "local", "uses_forecast": True}
            if record["kind"] == "formulation":
                formulations.add(label)
                if record.get("role") != "exact":
                    inexact.add(label)
            if record.get("uses_forecast"):
                readers.add(label)
        return cls(frozenset(formulations), frozenset(inexact), frozenset(readers))


def formulation_steps(steps: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Rows of the formulations (`kinds`)."""
    return steps[steps["strategy"].astype(str).isin(kinds.formulations)]


def convergence(steps: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Per case × formulation × k: steps with each status (count and share %); for an
    exact model's, the ok steps certified by the relaxation or by IPOPT (or on a three-phase
    feeder by its SDP relaxation or, without a decision, by the power flow's point proven
    the only one — where they certified one) and the steps with a lower bound."""
    sub = formulation_steps(steps, kinds)
    if sub.empty:
        return pd.DataFrame()
    counts = pd.crosstab([sub["case"], sub["strategy"], sub["k"]], sub["status"])
    for status in STATUSES:
        if status not in counts:
            counts[status] = 0
    extra = [c for c in counts.columns if c not in STATUSES]
    counts = counts[list(STATUSES) + extra]
    counts.columns.name = None
    total = counts.sum(axis=1)
    out = counts.copy()
    out.insert(0, "steps", total)
    out["not ok %"] = 100.0 * (total - counts["ok"]) / total
    ac = ~sub["strategy"].astype(str).isin(kinds.inexact)  # who certified the AC OPF's ok steps
    inexact = out.index.get_level_values("strategy").isin(kinds.inexact)
    shown = (CERTIFIED_BY_SDP, CERTIFIED_BY_UNIQUE)  # a three-phase run's: shown where they certified a step
    three_phase = tuple(c for c in shown if (sub["certified_by"] == c).any())
    for solver in (CERTIFIED_BY_SOCP, CERTIFIED_BY_IPOPT) + three_phase:
        picked = sub[ac & (sub["status"] == "ok") & (sub["certified_by"] == solver)]
        out[f"ok, certified by {solver}"] = (
            picked.groupby(["case", "strategy", "k"]).size().reindex(out.index, fill_value=0).where(~inexact).astype("Int64")
        )
    bounded = sub[ac].groupby(["case", "strategy", "k"])["lower_bound_kw"].count()  # a sample of a long three-phase run's
    out["steps with a bound"] = bounded.reindex(out.index, fill_value=0).where(~inexact).astype("Int64")
    return order(out.reset_index())


def failure_reasons(steps: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Steps not "ok" per case × formulation × status × solver return status."""
    sub = formulation_steps(steps, kinds)
    sub = sub[sub["status"] != "ok"]
    if sub.empty:
        return pd.DataFrame(columns=["case", "strategy", "status", "solver_status", "fallback", "steps"])
    out = sub.groupby(["case", "strategy", "status", "solver_status", "fallback"]).size().rename("steps").reset_index()
    return order(out)


def solver_stats(steps: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Solver iterations and solve times (ms) per case × formulation: median, 90th percentile,
    max; where a formulation predicts voltages (an approximation's `vm_error_pu`), its
    largest error against the power flow at its setpoints (p.u.)."""
    sub = formulation_steps(steps, kinds)
    if sub.empty:
        return pd.DataFrame()
    g = sub.groupby(["case", "strategy"])
    out = pd.DataFrame(
        {
            "steps": g.size(),
            "iterations median": g["iterations"].median(),
            "iterations p90": g["iterations"].quantile(0.9),
            "iterations max": g["iterations"].max(),
            "solve ms median": g["solver_ms"].median(),
            "solve ms p90": g["solver_ms"].quantile(0.9),
            "solve ms max": g["solver_ms"].max(),
            "solve s total": g["solver_ms"].sum() / 1e3,
        }
    )
    if "vm_error_pu" in sub:
        out["max |V| error p.u."] = g["vm_error_pu"].max()
    return order(out.reset_index())


def paper_setup(summary: pd.DataFrame, steps: pd.DataFrame | None) -> pd.DataFrame:
    """The paper's OPF setup (`registry.PAPER_OPF`) beside our AC OPF and LFMA, per case × k
    × night mode (forecast off): energy kWh, and the paper setup's failed steps by cause."""
    sub = summary[(summary["forecast"] == "off") & summary["strategy"].isin([PAPER_RULES[-1], REFERENCE_OPTIMUM, PAPER_OPF])]
    if not (sub["strategy"] == PAPER_OPF).any():
        return pd.DataFrame()
    out = sub.pivot_table(index=["case", "night_mode", "k"], columns="strategy", values="energy_kwh", aggfunc="first")
    out.columns = [f"{c} kWh" for c in out.columns]
    if steps is not None:
        paper_steps = steps[(steps["strategy"] == PAPER_OPF) & (steps["forecast"] == "off")]
        causes = pd.crosstab([paper_steps["case"], paper_steps["night_mode"], paper_steps["k"]], paper_steps["status"])
        for status in ("infeasible", "solver-failed", "fallback-no-action"):
            out[f"{PAPER_OPF} {status}"] = causes[status] if status in causes else 0
    return out.reset_index()


def night(summary: pd.DataFrame) -> pd.DataFrame:
    """Energy per night mode (forecast off) per case × strategy × k, and the reduction %
    of keeping PV connected (and of connected-q) vs disconnected at night."""
    sub = summary[summary["forecast"] == "off"]
    table = sub.pivot_table(index=["case", "strategy", "k"], columns="night_mode", values="energy_kwh", aggfunc="first")
    table.columns = [str(c) for c in table.columns]
    if "disconnected" in table:
        for mode in ("connected", "connected-q"):
            if mode in table:
                table[f"{mode} vs disconnected %"] = 100.0 * (1 - table[mode] / table["disconnected"])
    return order(table.reset_index())


def night_vs_paper(summary: pd.DataFrame, k: float = 0.0) -> pd.DataFrame:
    """The paper's night-hour table beside ours at reserve `k` (forecast off)."""
    rows = []
    ours = summary[(summary["forecast"] == "off") & np.isclose(summary["k"], k)]
    for case in sorted(ours["case"].unique()):
        for strategy in paper.NIGHT_TABLE["connected"]:
            theirs = {mode: float(paper.NIGHT_TABLE[mode][strategy][1]) for mode in ("connected", "disconnected")}
            mine = {}
            for mode in ("connected", "disconnected", "connected-q"):
                hit = ours[(ours["case"] == case) & (ours["strategy"] == strategy) & (ours["night_mode"] == mode)]
                mine[mode] = float(hit["energy_kwh"].iloc[0]) if len(hit) else np.nan
            rows.append(
                {"case": case, "strategy": strategy}
                | {f"paper {mode} kWh": e for mode, e in theirs.items()}
                | {f"ours {mode} kWh": e for mode, e in mine.items()}
                | {
                    "paper reduction %": 100 * (1 - theirs["connected"] / theirs["disconnected"]),
                    "ours reduction %": 100 * (1 - mine["connected"] / mine["disconnected"]),
                }
            )
    return pd.DataFrame(rows)


def gap(summary: pd.DataFrame) -> pd.DataFrame:
    """Energy vs the certified SOCP lower bound per case × strategy × k × night mode (forecast off)."""
    sub = summary[summary["forecast"] == "off"]
    cols = CONFIG + ["energy_kwh", "lower_bound_kwh", "gap_kwh", "gap_pct", "certified_share"]
    return order(sub[[c for c in cols if c in sub.columns]])


def voltage(summary: pd.DataFrame) -> pd.DataFrame:
    """Per case × strategy (over every k, night mode and forecast): steps outside the case's
    limits, lowest and highest voltage — over the steps with a converged power flow,
    counted beside them (a diverged step has no voltage figure)."""
    g = summary.groupby(["case", "strategy"])
    out = pd.DataFrame(
        {
            "configurations": g.size(),
            "steps": g["steps"].sum(),
            **{c: g[c].sum() for c in figure_steps(summary)},
            "steps outside limits": g["voltage_violation_steps"].sum(),
            "vmin_pu": g["vmin_pu"].min(),
            "vmax_pu": g["vmax_pu"].max(),
        }
    )
    return order(out.reset_index())


def excursions(summary: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Algorithm 3 (forecast on): steps whose setpoint exceeds the capability at P^C, and the largest excess."""
    sub = summary[(summary["forecast"] != "off") & summary["strategy"].astype(str).isin(kinds.forecast_readers)]
    return order(sub[CONFIG + ["steps", "excursion_steps", "max_excursion_mvar"]])


def forecast_metrics(forecast: dict[str, dict]) -> pd.DataFrame:
    """Metrics of each forecast JSON beside the paper's Table I."""
    rows = []
    for dataset, data in forecast.items():
        for model, m in data.get("metrics", {}).items():
            ref = paper.FORECAST_TABLE.get(dataset, {}).get(model, (np.nan, np.nan))
            rows.append(
                {
                    "dataset": dataset,
                    "model": model,
                    "MSE (scaled)": m.get("mse_scaled"),
                    "MAPE %": m.get("mape_pct"),
                    "MAE kW": m.get("mae_kw"),
                    "RMSE kW": m.get("rmse_kw"),
                    "skill": m.get("skill"),
                    "fit s": m.get("fit_s"),
                    "paper MSE": ref[0],
                    "paper MAPE %": ref[1],
                }
            )
    return pd.DataFrame(rows)


def recovery(fault: pd.DataFrame) -> pd.DataFrame:
    """Recovery time at the faulted bus per simulation, and the time added vs no action
    (`dynamics.recovery.recovery_table`)."""
    rec = recovery_table(fault)
    return order(rec[RECOVERY_KEYS + ["recovery_ms", "status", "vmin_pu", "margin_pu", "added_ms"]])


def recovery_pivot(rec: pd.DataFrame, variant: str = "reference") -> pd.DataFrame:
    """Recovery ms per (case, fault bus, strategy, forecast) × k for one model variant."""
    sub = rec[rec["variant"] == variant]
    table = sub.pivot_table(
        index=["case", "fault_bus", "strategy", "forecast"], columns="k", values="recovery_ms", aggfunc="first"
    )
    table.columns = [f"k={k:g}" for k in table.columns]
    return order(table.reset_index())


def sensitivity(rec: pd.DataFrame) -> pd.DataFrame:
    """Mean recovery and added time per model variant × strategy (over fault buses, k, forecast)."""
    g = rec.groupby(["case", "variant", "strategy"])
    out = pd.DataFrame(
        {
            "simulations": g.size(),
            "recovered": g["recovery_ms"].count(),
            "recovery ms mean": g["recovery_ms"].mean(),
            "added ms mean": g["added_ms"].mean(),
            "added ms min": g["added_ms"].min(),
            "added ms max": g["added_ms"].max(),
        }
    )
    return order(out.reset_index())


def convergence_summary(summary: pd.DataFrame, kinds: Kinds) -> pd.DataFrame:
    """Per case × formulation × k, over every night mode (forecast off): steps, steps not ok
    and the share of steps whose point is a certified AC optimum (by the SOCP or by IPOPT;
    NaN for a relaxation or an approximation, whose point is not certified) — from the
    summary, without the per-step table."""
    sub = summary[(summary["forecast"] == "off") & summary["strategy"].astype(str).isin(kinds.formulations)]
    g = sub.assign(certified=sub["certified_share"] * sub["steps"]).groupby(["case", "strategy", "k"], sort=False)
    out = g.agg(steps=("steps", "sum"), not_ok_steps=("not_ok_steps", "sum"), certified=("certified", "sum")).reset_index()
    inexact = out["strategy"].astype(str).isin(kinds.inexact)
    out["certified optimal %"] = np.where(inexact, np.nan, 100.0 * out.pop("certified") / out["steps"])
    return order(out)


def wall_times(summary: pd.DataFrame) -> pd.DataFrame:
    """Wall and solver time (s) per configuration."""
    return order(summary[CONFIG + ["steps", "wall_s", "solver_s"]])


SHOWN_BOARD = ["case", "k", "rank", "strategy", "energy_kwh", "curtailed_kwh", "gap_eq_kwh", "gap_eq_pct", "share_eq_pct"]
SHOWN_BOARD += ["loss_only_share_pct", "voltage_violation_min", "max_violation_pu", "not_settled_steps", "not_ok_steps"]
SHOWN_BOARD += ["recovery_added_ms"]
"""The leaderboard's columns the report shows, in its order (energy and minutes say what
the average losses and the violation steps would)."""

LEADERBOARD_COLUMNS = [
    "case",
    "k",
    "strategy",
    "energy_kwh",
    "curtailed_kwh",
    "cost_kwh",
    "frontier_kwh",
    "gap_eq_kwh",
    "gap_eq_pct",
    "share_eq_pct",
    "loss_only_share_pct",
    "avg_loss_kw",
    "savings_pct",
    "voltage_violation_min",
    "max_violation_pu",
    "voltage_violation_steps",
    "not_settled_steps",
    "not_ok_steps",
    "below_frontier_steps",
    "frontier_curtails",
    "recovery_added_ms",
]
SHARES = (
    "Shares: at equal compliance, (E_no-action − C)/(E_no-action − F) with C the configuration's losses plus "
    "curtailed energy and F the AC OPF with the voltage band widened, step by step, just enough to cover the "
    "configuration's own excursion beyond it, and at the capability its setpoints used (the frontier) — never "
    "above 100 %, the gap C − F never below 0 (up to the optimum being global: below-frontier steps count where "
    "it is not); a configuration with setpoints beyond the DER's capability (Algorithm 3 without safe) has none; "
    "loss-only, (E_no-action − E)/(E_no-action − E_acopf), which compares with an optimum that holds the band "
    "whatever the configuration does, so a rule that leaves the band can exceed 100 % there."
)
"""What the report's shares mean, said wherever it prints one."""


def _recovery_added(rec: pd.DataFrame | None) -> dict[tuple, float]:
    """(case, strategy, k) → mean recovery time added over no action (ms) at the faulted bus,
    forecast off, the reference model variant (or the first), over the fault buses."""
    if rec is None or rec.empty:
        return {}
    variants = sorted(rec["variant"].unique())
    sub = rec[(rec["forecast"] == "off") & (rec["variant"] == ("reference" if "reference" in variants else variants[0]))]
    mean = sub.groupby(["case", "strategy", "k"])["added_ms"].mean()
    return {(c, s, float(k)): float(v) for (c, s, k), v in mean.items()}


def at_equal_compliance(summary: pd.DataFrame) -> bool:
    """Whether `summary` holds the gaps at equal compliance (a run before the frontier does not)."""
    return "gap_eq_kwh" in summary.columns and bool(summary["gap_eq_kwh"].notna().any())


def leaderboard(
    summary: pd.DataFrame, night_mode: str = REFERENCE_NIGHT, recovery: pd.DataFrame | None = None, baseline: bool = False
) -> pd.DataFrame:
    """Per case × k (forecast off, one night mode), every rule and formulation other than
    the baseline at equal compliance (`SHARES`): its energy of losses and curtailed energy,
    the gap to the frontier at its own compliance (kWh and % of the frontier's) and its
    share there, the loss-only share beside it, minutes outside the case's voltage limits
    and the worst excursion beyond them (p.u.), not-settled, not-ok and below-frontier
    steps, and — given a fault study's `recovery` table — the recovery time it adds over
    no action (mean over the fault buses, ms); ranked per case and k by the gap at equal
    compliance (ties: fewer minutes outside first), or by energy where the summary was
    written before the frontier; `baseline`: the baseline's row too. A summary written
    before a column existed gives NaN there."""
    sub = summary[(summary["forecast"] == "off") & (summary["night_mode"] == night_mode)]
    added = _recovery_added(recovery)
    rows = []
    for (case, k), grp in sub.groupby(["case", "k"], sort=False):
        ref = grp.loc[grp["strategy"] == REFERENCE_OPTIMUM, "energy_kwh"]
        na = grp["no_action_kwh"].iloc[0]
        reduction = na - float(ref.iloc[0]) if len(ref) else np.nan
        for r in (grp if baseline else grp[grp["strategy"] != BASELINE]).to_dict(orient="records"):
            share = 100 * (na - r["energy_kwh"]) / reduction if reduction > TOL_KWH else np.nan
            rows.append(
                {c: r.get(c, np.nan) for c in LEADERBOARD_COLUMNS}
                | {
                    "case": case,
                    "k": k,
                    "loss_only_share_pct": share,
                    "recovery_added_ms": added.get((case, r["strategy"], float(k)), np.nan),
                }
            )
    out = pd.DataFrame(rows, columns=LEADERBOARD_COLUMNS)
    if out.empty:
        return out
    if recovery is None or recovery.empty:
        out = out.drop(columns="recovery_added_ms")
    by = ["gap_eq_kwh", "voltage_violation_min"] if at_equal_compliance(summary) else ["energy_kwh"]
    out = out.sort_values(["case", "k", *by], kind="stable", na_position="last")
    out["rank"] = out.groupby(["case", "k"]).cumcount() + 1
    out["rank"] = out["rank"].where(out[by[0]].notna()).astype("Int64")  # none without a figure
    return out.reset_index(drop=True)


def without_optimum(summary: pd.DataFrame) -> list[tuple[str, float, int]]:
    """(case, k, steps) where the reference optimum (forecast off, PV connected at night)
    is ok at no step and reduces no loss (every step fell back to no action) — the
    leaderboard's share is undefined there for want of an optimum, not of a reduction."""
    ref = summary[
        (summary["strategy"] == REFERENCE_OPTIMUM) & (summary["forecast"] == "off") & (summary["night_mode"] == REFERENCE_NIGHT)
    ]
    none = ref[(ref["not_ok_steps"] >= ref["steps"]) & ~(ref["no_action_kwh"] - ref["energy_kwh"] > TOL_KWH)]
    return [(str(r.case), float(r.k), int(r.steps)) for r in none.itertuples()]


def share_undefined(summary: pd.DataFrame, night_mode: str = REFERENCE_NIGHT) -> list[tuple[str, float, str]]:
    """(case, k, why) wherever the `leaderboard`'s loss-only share of the AC OPF's loss reduction is
    not given (—) for every row: the run has no AC OPF (or no baseline) there, one of
    their energies is not known (a step without a figure), or the optimum saves nothing.
    The case of an optimum that exists at no step is `without_optimum`'s, left to it."""
    sub = summary[(summary["forecast"] == "off") & (summary["night_mode"] == night_mode)]
    none = {(c, k) for c, k, _ in without_optimum(summary)} if night_mode == REFERENCE_NIGHT else set()
    out = []
    for (case, k), grp in sub.groupby(["case", "k"], sort=False):
        if (str(case), float(k)) in none:
            continue
        ref = grp.loc[grp["strategy"] == REFERENCE_OPTIMUM, "energy_kwh"]
        na = grp["no_action_kwh"].iloc[0]
        if ref.empty:
            why = f"the run has no {REFERENCE_OPTIMUM} configuration (add it to --strategies: the share is of its loss reduction)"
        elif not np.isfinite(na):
            why = f"the run has no {BASELINE} row (forecast off) to measure the reduction from"
        elif not np.isfinite(ref.iloc[0]):
            why = f"the {REFERENCE_OPTIMUM}'s energy is not known (a step without a figure)"
        elif not na - float(ref.iloc[0]) > TOL_KWH:
            why = f"the {REFERENCE_OPTIMUM} saves no loss here ({float(ref.iloc[0]):.6g} kWh against {na:.6g} kWh with no action)"
        else:
            continue
        out.append((str(case), float(k), why))
    return out


LOCAL_COLUMNS = [
    "case",
    "k",
    "rank",
    "strategy",
    "train_share_eq_pct",
    "test_share_eq_pct",
    "test_gap_eq_pct",
    "train_loss_only_share_pct",
    "test_loss_only_share_pct",
    "test_energy_kwh",
    "test_curtailed_kwh",
    "train_voltage_violation_min",
    "test_voltage_violation_min",
    "test_max_violation_pu",
    "train_not_settled_steps",
    "test_not_settled_steps",
]


def how_close(
    summary: pd.DataFrame, kinds: Kinds, train: pd.DataFrame | None = None, model_of: dict[str, str] | None = None
) -> pd.DataFrame:
    """Per case × k (forecast off, PV connected at night): every local rule — no action,
    the paper's, the rules in force, the learned ones — at equal compliance (`SHARES`) on
    the test period (the run, `summary`) and on the training period (`train`, the run's
    training summary, whose cases are the cases' models: `model_of` maps a case to its
    model's name, default itself): its share there, its gap on the test period, the
    loss-only share beside them, with each period's minutes outside the voltage limits,
    the test's worst excursion, energy, curtailed energy and not-settled steps; ranked by
    the test period's gap at equal compliance (the `leaderboard`'s rank). NaN where a side
    lacks the rule or the figure."""
    test = leaderboard(summary, baseline=True)
    test = test[~test["strategy"].astype(str).isin(kinds.formulations)].copy()
    test["rank"] = test.groupby(["case", "k"])["rank"].rank(method="first").astype("Int64")
    out = pd.DataFrame(
        {
            "case": test["case"],
            "k": test["k"],
            "rank": test["rank"],
            "strategy": test["strategy"],
            "test_share_eq_pct": test["share_eq_pct"],
            "test_gap_eq_pct": test["gap_eq_pct"],
            "test_loss_only_share_pct": test["loss_only_share_pct"],
            "test_energy_kwh": test["energy_kwh"],
            "test_curtailed_kwh": test["curtailed_kwh"],
            "test_voltage_violation_min": test["voltage_violation_min"],
            "test_max_violation_pu": test["max_violation_pu"],
            "test_not_settled_steps": test["not_settled_steps"],
        }
    )
    if train is not None and not train.empty:
        side = leaderboard(train, baseline=True)
        side = side[
            ["case", "k", "strategy", "share_eq_pct", "loss_only_share_pct", "voltage_violation_min", "not_settled_steps"]
        ].rename(
            columns={
                "case": "model",
                "share_eq_pct": "train_share_eq_pct",
                "loss_only_share_pct": "train_loss_only_share_pct",
                "voltage_violation_min": "train_voltage_violation_min",
                "not_settled_steps": "train_not_settled_steps",
            }
        )
        out["model"] = out["case"].map(lambda c: (model_of or {}).get(c, c))
        out = out.merge(side, on=["model", "k", "strategy"], how="left").drop(columns="model")
    for column in LOCAL_COLUMNS:
        if column not in out:
            out[column] = np.nan
    return out[LOCAL_COLUMNS].sort_values(["case", "k", "rank"], kind="stable", na_position="last").reset_index(drop=True)


FRONTIER_SHOWN = ["case", "k", "curtail", "eps_pu", "steps", "energy_kwh", "bound_kwh", "voltage_violation_min"]
FRONTIER_SHOWN += ["max_violation_pu"]
FRONTIER_SHOWN += ["no_optimum_steps", "solved_steps"]


def frontier_table(frontier: pd.DataFrame, night_mode: str = REFERENCE_NIGHT) -> pd.DataFrame:
    """The frontier of losses against compliance per case and k (one night mode), the plain
    AC OPF's over every step and, over the steps where a configuration curtailed, the one
    that may curtail (losses + curtailed energy): per ε the steps, the optimum's energy,
    its certified bound's, its minutes outside the (unwidened) band and worst excursion,
    the steps without an optimum, the steps solved at that ε."""
    sub = frontier[frontier["night_mode"] == night_mode]
    return sub[FRONTIER_SHOWN].sort_values(["case", "k", "curtail", "eps_pu"], kind="stable").reset_index(drop=True)
