"""The paper's claims, each with a verdict computed from our tables — never typed in.

The claims are about the paper's configurations — no action (`registry.BASELINE`), LLMA
and LFMA (`registry.PAPER_RULES`), its OPF (`REFERENCE_OPTIMUM`, `PAPER_OPF`) — and look
only at those rows: other rules in the run (the grid codes', plugins) never change a verdict.

`claims(inputs)` returns one `Claim` per claim: the paper's figure, ours, and a verdict
"holds" / "does not hold" / "not comparable" with the reason (a missing input makes a
claim "not comparable" and names the command that produces it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd

from opfbench.registry.references import BASELINE, PAPER_OPF, PAPER_RULES, REFERENCE_OPTIMUM
from opfbench.report import paper_figures as paper
from opfbench.report import tables
from opfbench.report.inputs import Inputs

HOLDS, FAILS, NA = "holds", "does not hold", "not comparable"
TOL_KWH = 1e-6
TOL_MS = 0.5
"""Recovery times closer than this (ms) count as equal (the fault study's time step is ≥ 1 ms)."""


@dataclass(frozen=True)
class Claim:
    claim: str
    paper: str
    ours: str
    verdict: str
    reason: str


def _missing(claim: str, figure: str, inputs: Inputs, needed: str) -> Claim:
    return Claim(claim, figure, "—", NA, f"no {needed}: run {inputs.missing.get(needed, 'the producing command')}")


def _off(summary: pd.DataFrame) -> pd.DataFrame:
    return summary[summary["forecast"] == "off"]


def _energy(summary: pd.DataFrame, strategies: list[str]) -> pd.DataFrame:
    """Energy kWh, forecast off, one column per strategy, rows (case, night mode, k)."""
    sub = _off(summary)
    sub = sub[sub["strategy"].isin(strategies)]
    return sub.pivot_table(index=["case", "night_mode", "k"], columns="strategy", values="energy_kwh", aggfunc="first")


def _complete(table: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """The rows of `table` with every figure, and a note on the rows left out (a
    configuration with a step without a figure — pf-diverged, rule-non-finite — has no energy)."""
    full = table.dropna()
    left_out = len(table) - len(full)
    return full, (f"; {left_out} configuration(s) left out: a step without a loss figure" if left_out else "")


LLMA, LFMA = PAPER_RULES


def _where(index: tuple) -> str:
    case, mode, k = index
    return f"{case}, night {mode}, k={k:g}"


def _ordered(e: pd.DataFrame) -> pd.Series:
    """Per row of an energy pivot: LFMA < LLMA < no action, strictly."""
    return (e[LFMA] < e[LLMA] - TOL_KWH) & (e[LLMA] < e[BASELINE] - TOL_KWH)


def ranking(inputs: Inputs) -> Claim:
    claim = "LFMA < LLMA < no action at every k"
    na, ll, lf = (
        paper.NIGHT_TABLE["connected"][BASELINE][1],
        paper.NIGHT_TABLE["connected"][LLMA][1],
        paper.NIGHT_TABLE["connected"][LFMA][1],
    )
    figure = f"LFMA {lf} < LLMA {ll} < no action {na} kWh (night connected)"
    if inputs.summary is None:
        return _missing(claim, figure, inputs, "summary.csv")
    e = _energy(inputs.summary, [BASELINE, LLMA, LFMA])
    if e.empty or e.shape[1] < 3:
        return Claim(claim, figure, "—", NA, f"the run has not all of {BASELINE}, {LLMA} and {LFMA}")
    e, left_out = _complete(e)
    if e.empty:
        return Claim(claim, figure, "—", NA, "no configuration has an energy for all three" + left_out)
    ok = _ordered(e)
    ours = f"ordered in {int(ok.sum())} of {len(ok)} (case, night mode, k) configurations{left_out}"
    if ok.all():
        return Claim(claim, figure, ours, HOLDS, "strict order in every configuration of the run")
    first = e.index[~ok][0]
    w = e.loc[first]
    return Claim(
        claim,
        figure,
        ours,
        FAILS,
        f"not ordered at {_where(first)}: LFMA {w[LFMA]:.2f}, LLMA {w[LLMA]:.2f}, no action {w[BASELINE]:.2f} kWh",
    )


def ranking_per_case(summary: pd.DataFrame) -> pd.DataFrame:
    """The ranking claim (LFMA < LLMA < no action) checked per case over its (night mode, k)
    configurations, forecast off: how many are ordered, and the verdict of that case."""
    e = _energy(summary, [BASELINE, LLMA, LFMA]).dropna()
    rows = []
    for case in dict.fromkeys(summary["case"]):
        sub = e[e.index.get_level_values("case") == case] if len(e) else e
        if sub.empty or sub.shape[1] < 3:
            rows.append({"case": case, "ordered": 0, "configurations": 0, "verdict": NA, "first exception": ""})
            continue
        ok = _ordered(sub)
        first = "" if ok.all() else _where(sub.index[~ok][0])
        rows.append(
            {
                "case": case,
                "ordered": int(ok.sum()),
                "configurations": len(ok),
                "verdict": HOLDS if ok.all() else FAILS,
                "first exception": first,
            }
        )
    return pd.DataFrame(rows)


def forecast_savings(inputs: Inputs) -> Claim:
    claim = "Forecast-aware rules cut losses up to 30 % vs no action"
    figure = f"up to {paper.FORECAST_SAVINGS_PCT:g} %"
    if inputs.summary is None:
        return _missing(claim, figure, inputs, "summary.csv")
    s = inputs.summary
    aware = s[(s["forecast"] != "off") & s["strategy"].isin(PAPER_RULES)].dropna(subset=["savings_pct"])
    if aware.empty:
        return Claim(claim, figure, "—", NA, "the run has no forecast-aware (forecast ≠ off) LLMA/LFMA configuration")
    best = aware.loc[aware["savings_pct"].idxmax()]
    base = s[
        (s["forecast"] == "off")
        & (s["case"] == best["case"])
        & (s["strategy"] == best["strategy"])
        & (s["night_mode"] == best["night_mode"])
        & np.isclose(s["k"], best["k"])
    ]
    added = best["savings_pct"] - float(base["savings_pct"].iloc[0]) if len(base) else np.nan
    ours = (
        f"best {best['savings_pct']:.1f} % ({best['strategy']}, forecast {best['forecast']}, k={best['k']:g}, "
        f"night {best['night_mode']}); the forecast itself adds {added:.1f} points"
    )
    floor = paper.FORECAST_SAVINGS_PCT - 5.0
    if best["savings_pct"] >= floor:
        return Claim(claim, figure, ours, HOLDS, f"best saving ≥ {floor:g} % (within 5 points of the claimed 30 %)")
    return Claim(claim, figure, ours, FAILS, f"best saving {best['savings_pct']:.1f} % < {floor:g} %")


def night_connected(inputs: Inputs) -> Claim:
    claim = "Keeping PV connected at night cuts losses 4–15 %"
    lo, hi = paper.NIGHT_SAVINGS_PCT
    own = [
        100 * (1 - paper.NIGHT_TABLE["connected"][s][1] / paper.NIGHT_TABLE["disconnected"][s][1])
        for s in (*PAPER_RULES, REFERENCE_OPTIMUM)
    ]
    figure = f"{lo:g}–{hi:g} % (its own table: {min(own):.1f}–{max(own):.1f} %)"
    if inputs.summary is None:
        return _missing(claim, figure, inputs, "summary.csv")
    e = _off(inputs.summary)
    e = e[e["strategy"].isin([*PAPER_RULES, REFERENCE_OPTIMUM])].pivot_table(
        index=["case", "strategy", "k"], columns="night_mode", values="energy_kwh", aggfunc="first"
    )
    if not {"connected", "disconnected"} <= set(e.columns):
        return Claim(claim, figure, "—", NA, "the run lacks the connected or the disconnected night mode")
    cut, left_out = _complete(100 * (1 - e["connected"] / e["disconnected"]))
    if cut.empty:
        return Claim(claim, figure, "—", NA, "no configuration has an energy in both night modes" + left_out)
    ours = f"{cut.min():.1f}–{cut.max():.1f} % (LLMA, LFMA, AC OPF over k){left_out}"
    if "connected-q" in e.columns:
        q = (100 * (1 - e["connected-q"] / e["disconnected"])).dropna()
        ours += f"; with Q at night (connected-q) {q.min():.1f}–{q.max():.1f} %"
    inside = cut.between(lo, hi)
    if inside.all():
        return Claim(claim, figure, ours, HOLDS, f"every reduction within [{lo:g}, {hi:g}] %")
    return Claim(claim, figure, ours, FAILS, f"{int((~inside).sum())} of {len(cut)} reductions outside [{lo:g}, {hi:g}] %")


def _beats(inputs: Inputs, opf: str, claim: str) -> Claim:
    figure = (
        f"LFMA {paper.NIGHT_TABLE['connected'][LFMA][1]} < OPF {paper.NIGHT_TABLE['connected'][REFERENCE_OPTIMUM][1]} kWh "
        f"(connected), {paper.NIGHT_TABLE['disconnected'][LFMA][1]} < "
        f"{paper.NIGHT_TABLE['disconnected'][REFERENCE_OPTIMUM][1]} (disconnected)"
    )
    if inputs.summary is None:
        return _missing(claim, figure, inputs, "summary.csv")
    e = _energy(inputs.summary, [LFMA, opf])
    if e.shape[1] < 2:
        return Claim(claim, figure, "—", NA, f"the run has not both {LFMA} and {opf}")
    e, left_out = _complete(e)
    if e.empty:
        return Claim(claim, figure, "—", NA, f"no configuration has an energy for both {LFMA} and {opf}" + left_out)
    wins = e[LFMA] < e[opf] - TOL_KWH
    diff = 100 * (e[LFMA] / e[opf] - 1)
    ours = (
        f"LFMA lower in {int(wins.sum())} of {len(wins)} configurations (LFMA vs {opf}: {diff.min():+.1f} … "
        f"{diff.max():+.1f} %){left_out}"
    )
    if wins.all():
        return Claim(claim, figure, ours, HOLDS, f"LFMA uses less energy than {opf} in every configuration")
    return Claim(
        claim,
        figure,
        ours,
        FAILS,
        f"{opf} uses less or equal energy in {int((~wins).sum())} configuration(s)"
        + ("; a converged OPF under the same limits cannot lose to a feasible local rule" if opf == REFERENCE_OPTIMUM else ""),
    )


def lfma_vs_opf(inputs: Inputs) -> Claim:
    return _beats(inputs, REFERENCE_OPTIMUM, "LFMA beats the centralized OPF (our AC OPF: fallback chain, slack may export)")


def lfma_vs_paper_opf(inputs: Inputs) -> Claim:
    return _beats(
        inputs,
        PAPER_OPF,
        "LFMA beats the centralized OPF under the paper's setup (acopf-paper: slack may not export, failure → no action)",
    )


def best_forecaster(inputs: Inputs) -> Claim:
    claim = "Wavelet-CNN-LSTM is the best forecaster"
    figure = "lowest MSE and MAPE on PV and wind (Table I)"
    if not inputs.forecast:
        return _missing(claim, figure, inputs, "forecast")
    m = tables.forecast_metrics(inputs.forecast)
    parts, wins = [], []
    for dataset, grp in m.groupby("dataset"):
        grp = grp.dropna(subset=["MSE (scaled)", "MAPE %"])
        if grp.empty or "wavelet-cnn-lstm" not in set(grp["model"]):
            return Claim(claim, figure, "—", NA, f"the {dataset} forecast run has no wavelet-cnn-lstm metrics")
        by_mse = grp.loc[grp["MSE (scaled)"].idxmin(), "model"]
        by_mape = grp.loc[grp["MAPE %"].idxmin(), "model"]
        parts.append(f"{dataset}: best MSE {by_mse}, best MAPE {by_mape}")
        wins += [by_mse == "wavelet-cnn-lstm", by_mape == "wavelet-cnn-lstm"]
    ours = "; ".join(parts)
    if all(wins):
        return Claim(claim, figure, ours, HOLDS, "wavelet-cnn-lstm has the lowest MSE and MAPE on every dataset")
    return Claim(claim, figure, ours, FAILS, "another model has a lower MSE or MAPE on at least one dataset")


def _recovery(inputs: Inputs) -> pd.DataFrame | None:
    if inputs.fault is None or inputs.fault.empty:
        return None
    rec = tables.recovery(inputs.fault)
    return rec[rec["variant"] == "reference"] if (rec["variant"] == "reference").any() else rec


def recovery_added(inputs: Inputs, strategy: str) -> Claim:
    lo, hi = paper.RECOVERY_ADDED_MS[strategy]
    claim = f"{strategy.upper()} adds {lo:g}–{hi:g} ms to the recovery time (vs no action)"
    figure = f"{lo:g}–{hi:g} ms (RTDS, recovery ≈ 0.5 s)"
    rec = _recovery(inputs)
    if rec is None:
        return _missing(claim, figure, inputs, "fault.parquet")
    added = rec[rec["strategy"] == strategy]["added_ms"].dropna()
    if added.empty:
        return Claim(claim, figure, "—", NA, f"no recovered {strategy} simulation with a recovered no-action peer")
    ours = f"{added.min():+.1f} … {added.max():+.1f} ms over {len(added)} simulations (faulted bus, reference model)"
    inside = added.between(lo - TOL_MS, hi + TOL_MS)
    if inside.all():
        return Claim(claim, figure, ours, HOLDS, f"every added time within [{lo:g}, {hi:g}] ms")
    return Claim(claim, figure, ours, FAILS, f"{int((~inside).sum())} of {len(added)} added times outside [{lo:g}, {hi:g}] ms")


def larger_k_faster(inputs: Inputs) -> Claim:
    claim = "Larger k recovers faster"
    figure = "recovery time falls as k grows (Figs. 5–6)"
    rec = _recovery(inputs)
    if rec is None:
        return _missing(claim, figure, inputs, "fault.parquet")
    rec = rec[rec["strategy"].isin([*PAPER_RULES, REFERENCE_OPTIMUM])].dropna(subset=["recovery_ms"])
    groups = [
        g.sort_values("k")["recovery_ms"].to_numpy()
        for _, g in rec.groupby(["case", "fault_bus", "strategy", "forecast", "variant"])
    ]
    groups = [g for g in groups if len(g) > 1]
    if not groups:
        return Claim(claim, figure, "—", NA, "the fault study has fewer than two k per (fault bus, strategy)")
    monotone = [bool(np.all(np.diff(g) <= TOL_MS)) for g in groups]
    ours = f"non-increasing in k in {sum(monotone)} of {len(groups)} (fault bus, strategy, forecast) series"
    if all(monotone):
        return Claim(claim, figure, ours, HOLDS, f"recovery never grows with k by more than {TOL_MS:g} ms")
    return Claim(claim, figure, ours, FAILS, f"recovery grows with k in {len(groups) - sum(monotone)} series")


def voltage_band(inputs: Inputs) -> Claim:
    lo, hi = paper.VOLTAGE_LIMITS_PU
    claim = f"Local rules keep voltages within [{lo:g}, {hi:g}] p.u."
    figure = f"[{lo:g}, {hi:g}] p.u. throughout"
    if inputs.summary is None:
        return _missing(claim, figure, inputs, "summary.csv")
    s = inputs.summary[inputs.summary["strategy"].isin(PAPER_RULES)]
    if s.empty:
        return Claim(claim, figure, "—", NA, "the run has no llma/lfma configuration")
    # voltages are over the steps with a figure; a pf-diverged or rule-non-finite step has none
    measured = int(s["pf_converged_steps"].sum()) if "pf_converged_steps" in s else int(s["steps"].sum())
    no_figure = int(s["steps"].sum()) - measured
    if measured == 0:
        return Claim(claim, figure, "—", NA, "no local-rule step has a voltage figure")
    vmin, vmax = s["vmin_pu"].min(), s["vmax_pu"].max()
    ours = f"LLMA/LFMA voltages {vmin:.4f} … {vmax:.4f} p.u. over {measured} steps"
    if not (vmin >= lo - 1e-6 and vmax <= hi + 1e-6):
        return Claim(claim, figure, ours, FAILS, "some step leaves the band")
    if no_figure:
        ours += f"; {no_figure} steps without a voltage figure"
        return Claim(claim, figure, ours, NA, f"{no_figure} steps have no voltage figure (pf-diverged or rule-non-finite)")
    return Claim(claim, figure, ours, HOLDS, "every step of every local-rule configuration within the band")


CLAIMS: tuple[Callable[[Inputs], Claim], ...] = (
    ranking,
    forecast_savings,
    night_connected,
    lfma_vs_opf,
    lfma_vs_paper_opf,
    best_forecaster,
    *(lambda inp, rule=rule: recovery_added(inp, rule) for rule in PAPER_RULES),
    larger_k_faster,
    voltage_band,
)


def claims(inputs: Inputs) -> list[Claim]:
    """Every claim of the paper checked against `inputs`."""
    return [check(inputs) for check in CLAIMS]
