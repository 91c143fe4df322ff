"""The report's sections, in order; each reads `Inputs` and never raises on a missing
input: the section says which command produces it."""

from __future__ import annotations

from typing import Callable

import pandas as pd

from opfbench.report import plots, tables
from opfbench.report.claims import claims, ranking_per_case
from opfbench.report.inputs import Inputs
from opfbench.report.page import Block, Section, table
from opfbench.study.price import DEFAULT_CURRENCY, DEFAULT_PRICE_PER_KWH, DEFAULT_PRICE_SOURCE


def _seconds(value: object) -> str:
    return f"{float(value):.1f} s" if isinstance(value, (int, float)) else "not recorded"


def _missing(inputs: Inputs, *names: str) -> list[Block]:
    return [Block("missing", text=name, command=inputs.missing[name]) for name in names if name in inputs.missing]


def _plots(found: list[plots.Plot]) -> list[Block]:
    return [Block("plot", plot=p) for p in found]


def _ders(ders: list[dict]) -> str:
    """The DER of a case: each one for a few, counts and total rating per kind for many."""
    if not ders:
        return "none"
    if len(ders) <= 8:
        return ", ".join(f"{d.get('kind')} at bus {d.get('bus')} ({d.get('rating_mw')} MW)" for d in ders)
    kinds: dict[str, list[float]] = {}
    for d in ders:
        kinds.setdefault(str(d.get("kind")), []).append(float(d.get("rating_mw") or 0.0))
    return f"{len(ders)} units (" + ", ".join(f"{k}: {len(v)}, {sum(v):.3g} MW" for k, v in kinds.items()) + ")"


def how_close(inputs: Inputs) -> Section:
    """The headline: every local rule against the optimum at its own voltage compliance, on
    the training period (where the run trained learned rules) and the test period, and the
    frontier of losses against compliance with each rule a point."""
    sec = Section(
        "local",
        "How close can a local rule get",
        "Per case and k (forecast off, PV connected at night), each communication-free rule — no action, the "
        "paper's LLMA and LFMA, the rules in force (IEEE 1547 Volt-VAR, Watt-VAR and Volt-Watt, constant PF, VDE "
        "cos φ(P) and Q(U)) and the rules learned from the certified optimum over a training period "
        "(learned-affine, learned-vv, learned-1547) — against the AC OPF at its own voltage compliance: the OPF "
        "with the voltage band widened, step by step, just enough to cover the rule's own excursion beyond it (the "
        "frontier). Ranked by the gap at equal compliance on the test period; the share there next to the "
        "training period's, each period's minutes outside the voltage limits beside them, and the loss-only share "
        "for comparison. " + tables.SHARES + " A case with line-z is the grid with perturbed line impedances; its "
        "learned rules were fitted on the unperturbed model, so its test column is the price of model error.",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    sec.blocks += _how_close_blocks(inputs, "")
    if inputs.train_summary is None:
        sec.add(
            Block(
                "note",
                text="The run trained no learned rule, so there is no training-period column: add e.g. "
                "--strategies ... learned-affine:train=2016-01-01..2016-10-01 with --period 2016-10-01..2017-01-01."
                + (" The committed studies below did: each a run of its own (docs/learned)." if inputs.studies else ""),
            )
        )
    for study in inputs.studies:
        if study.summary is not None:
            sec.add(Block("heading", text=f"A committed study: {study.run_dir.name}"))
            sec.add(_run_meta(f"docs/learned/{study.run_dir.name}", study.manifest or {}))
            sec.add(Block("note", text=TRAINING_TIME))
            sec.blocks += _how_close_blocks(study, f" — {study.run_dir.name}")
    return sec


TRAINING_TIME = (
    "The wall time is the test period's: the training optimum and the in-sample evaluation ran before it, as "
    "nested runs of their own (train/reference, train/learned)."
)
BEFORE_FRONTIER = (
    "This run was written before the frontier: its shares are loss-only (against the AC OPF that holds the "
    "voltage band, whatever the rule does) and its ranking by energy."
)


def _how_close_blocks(inputs: Inputs, name: str) -> list[Block]:
    """A run's local rules at equal compliance (train beside test), its fitted rules, its
    frontier figure and its share figure; `name` tells the run apart."""
    board = tables.how_close(inputs.summary, inputs.kinds(), inputs.train_summary, inputs.models())
    out = []
    if inputs.learned:
        fits = pd.DataFrame([{"file": ref} | row for ref, row in sorted(inputs.learned.items())])
        out.append(table(fits, f"The fitted rules{name} (each file a rule: NAME:params=FILE)"))
    if inputs.summary is not None and not tables.at_equal_compliance(inputs.summary):
        out.append(Block("note", text=BEFORE_FRONTIER))
    out.append(table(board, f"Local rules at equal compliance, training vs test period{name} (rank 1 = smallest gap)", 30))
    leader = tables.leaderboard(inputs.summary, baseline=True) if inputs.summary is not None else pd.DataFrame()
    return out + _plots(plots.frontier_vs_compliance(leader, inputs.frontier, name)) + _plots(plots.how_close(board, name))


def metadata(inputs: Inputs, price: tuple[float, str, str]) -> Section:
    sec = Section("metadata", "Run metadata")
    m = inputs.manifest
    if m is None:
        return sec.add(Block("note", text=f"Run folder {inputs.run_dir}."), *_missing(inputs, "manifest.json"))
    cfg, period = m.get("config", {}), m.get("period", {})
    versions = ", ".join(f"{k} {v}" for k, v in (m.get("versions") or {}).items())
    timings, machine = m.get("timings") or {}, m.get("machine") or {}
    cases = "; ".join(
        f"{name}: {c.get('buses')} buses, DER {_ders(c.get('ders', []))}, limits [{c.get('vmin_pu')}, {c.get('vmax_pu')}] p.u."
        + (f", own profiles: {c['series']}" if c.get("series") else "")
        for name, c in (m.get("cases") or {}).items()
    )
    items = [
        ("command", " ".join(str(a) for a in m.get("command") or [])),
        ("run folder", str(inputs.run_dir)),
        ("created (UTC)", str(m.get("created_utc"))),
        ("cases", cases or ", ".join(cfg.get("cases", []))),
        (
            "period",
            f"{cfg.get('period')}: {period.get('start')} → {period.get('end')}, {period.get('steps')} steps "
            f"of {cfg.get('step_minutes')} min",
        ),
        (
            "grid",
            f"strategies {', '.join(cfg.get('strategies', []))}; k {', '.join(f'{k:g}' for k in cfg.get('ks', []))}; "
            f"night modes {', '.join(cfg.get('night_modes', []))} (night {cfg.get('night')}); "
            f"forecast {', '.join(cfg.get('forecast', []))}",
        ),
        ("data sources", "; ".join(m.get("data_sources") or [])),
        ("energy price", f"{price[0]:g} {price[1]}/kWh — {price[2]}"),
        ("opfbench", f"{m.get('opfbench_version')} (git commit {m.get('git_commit') or 'not available'})"),
        ("versions", versions),
        ("machine", f"{machine.get('cores')} cores, {machine.get('platform')}"),
        (
            "wall time",
            f"{_seconds(timings.get('wall_s'))} total, {timings.get('workers')} workers, "
            f"scheduler {timings.get('scheduler') or 'local'}",
        ),
    ]
    sec.add(Block("meta", items=items))
    if inputs.summary is not None:
        sec.add(table(tables.wall_times(inputs.summary), "Wall and solver time per configuration (s)", collapse_over=0))
    return sec


def _no_figure_note(summary: pd.DataFrame) -> list[Block]:
    """A note on the configurations with steps that have no figure, by status."""
    bad = tables.without_figures(summary)
    if bad.empty:
        return []
    why = "; ".join(
        f"{status}, {reason}: {int(bad[column].sum())} steps"
        for column, (status, reason) in tables.NO_FIGURE.items()
        if column in bad.columns and bad[column].sum() > 0
    )
    return [
        Block(
            "note",
            text=f"{len(bad)} configuration(s) have steps without a loss or voltage figure ({why}): their energy, "
            "savings and gap are not given (—), and their average loss and voltages are over the steps with a "
            "figure (pf_converged_steps).",
        )
    ]


def _energy_tables(s: pd.DataFrame, price: tuple[float, str, str], over: str = "") -> list[Block]:
    """Energy per strategy × k for each night mode, then savings % and money saved per year
    vs no action with PV connected at night; `over` qualifies the period (e.g. " over the year")."""
    out = [
        table(tables.energy_pivot(s, mode), f"Energy losses{over} (kWh) per strategy and k, PV {mode} at night", collapse_over=60)
        for mode in ("connected", "disconnected", "connected-q")
        if mode in set(s["night_mode"])
    ]
    out.append(
        table(
            tables.energy_pivot(s, tables.REFERENCE_NIGHT, "savings_pct"),
            f"Savings vs no action{over} (%), PV connected at night",
            collapse_over=60,
        )
    )
    money = tables.losses(s, price[0])
    out.append(
        table(
            tables.energy_pivot(money, tables.REFERENCE_NIGHT, "money_per_year"),
            f"Money saved per year vs no action ({price[1]} at {price[0]:g}/kWh), PV connected at night",
            collapse_over=60,
        )
    )
    return out


def losses(inputs: Inputs, price: tuple[float, str, str]) -> Section:
    sec = Section(
        "losses",
        "Losses and savings",
        f"Average losses (kW), energy (kWh), savings vs no action (same case, k and night mode, forecast off) and "
        f"the money they save at {price[0]:g} {price[1]}/kWh ({price[2]}); per year = the run's daily "
        f"savings × 365.",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    s = inputs.summary
    sec.blocks += _no_figure_note(s)
    sec.blocks += _energy_tables(s, price)
    money = tables.losses(s, price[0])
    full = money.rename(columns={"money_per_day": f"{price[1]} per day", "money_per_year": f"{price[1]} per year"})
    sec.add(table(full, "Every configuration", collapse_over=0))
    if inputs.steps is not None:
        sec.blocks += _plots(plots.losses_day(inputs.steps))
    sec.blocks += _plots(plots.energy_vs_k(s))
    if inputs.der_q is not None:
        sec.blocks += _plots(plots.der_q_day(inputs.der_q))
    else:
        sec.blocks += _missing(inputs, "der_q.parquet")
    return sec


NO_OPTIMUM = (
    "{case}, k={k:g}: the AC OPF has no optimum at any of the {steps} steps (infeasible or failed: see the "
    "convergence section), so there is no reference and no share of its loss reduction (—)."
)
NO_SHARE = "{case}, k={k:g}: no loss-only share of the AC OPF's loss reduction (—): {why}."


def _share_notes(summary: pd.DataFrame, night_mode: str = tables.REFERENCE_NIGHT) -> list[Block]:
    """Why a leaderboard's share column is — for a case and k (`tables.share_undefined`,
    `tables.without_optimum`)."""
    notes = [Block("note", text=NO_OPTIMUM.format(case=c, k=k, steps=n)) for c, k, n in tables.without_optimum(summary)]
    notes = notes if night_mode == tables.REFERENCE_NIGHT else []
    return notes + [
        Block("note", text=NO_SHARE.format(case=c, k=k, why=why)) for c, k, why in tables.share_undefined(summary, night_mode)
    ]


def _shown(board: pd.DataFrame) -> pd.DataFrame:
    """A leaderboard's columns the report shows (`tables.SHOWN_BOARD`, those it has)."""
    return board[[c for c in tables.SHOWN_BOARD if c in board]]


def grids(inputs: Inputs) -> Section:
    """The leaderboard per case (every rule and formulation against the optimum at its own
    compliance), the frontier, and the ranking claim checked per grid ("the rules work on
    any feeder")."""
    sec = Section(
        "grids",
        "Leaderboard per case",
        "Every rule and formulation per case and k (forecast off, PV connected at night), ranked by its gap to the "
        "AC OPF at its own voltage compliance: energy of losses and curtailed energy, the gap and share at equal "
        "compliance, the loss-only share, minutes outside the case's voltage limits and the worst excursion beyond "
        "them, steps where a closed-loop rule did not settle (not-settled) or the strategy's status is not ok, and — "
        "with a fault study — the recovery time it adds over no action (mean over the fault buses, reference model, "
        "forecast off); the frontier of losses against compliance, with each configuration a point; then the "
        "paper's ranking claim LFMA < LLMA < no action checked on each grid separately. " + tables.SHARES,
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    notes = [
        (case, note) for case, info in ((inputs.manifest or {}).get("cases") or {}).items() for note in info.get("notes", [])
    ]
    for case, note in notes:
        sec.add(Block("note", text=f"{case}: {note}"))
    sec.blocks += _share_notes(inputs.summary)
    if not tables.at_equal_compliance(inputs.summary):
        sec.add(Block("note", text=BEFORE_FRONTIER))
    recovery = tables.recovery(inputs.fault) if inputs.fault is not None else None
    board = tables.leaderboard(inputs.summary, recovery=recovery)
    sec.add(table(_shown(board), "Leaderboard per case and k (rank 1 = smallest gap at equal compliance)", collapse_over=60))
    if inputs.frontier is not None:
        front = tables.frontier_table(inputs.frontier)
        sec.add(table(front, "The frontier: the AC OPF with the voltage band widened by ε (PV connected at night)", 40))
    sec.blocks += _plots(plots.frontier_vs_compliance(board, inputs.frontier))
    sec.blocks += _plots(plots.share_vs_costs(board))
    return sec.add(table(ranking_per_case(inputs.summary), "The ranking claim per grid (forecast off, every night mode and k)"))


def convergence(inputs: Inputs) -> Section:
    sec = Section(
        "convergence",
        "Convergence of the formulations",
        "Per formulation and k: steps of each status (ok; fallback-cold / fallback-socp / fallback-no-action: "
        "IPOPT failed, a fallback point was used; infeasible / solver-failed: no feasible point found, no "
        "action applied; pf-diverged: the setpoints' power flow did not converge).",
    )
    if inputs.steps is None:
        return sec.add(*_missing(inputs, "steps.parquet"))
    conv = tables.convergence(inputs.steps, inputs.kinds())
    if conv.empty:
        return sec.add(Block("note", text="The run has no formulation (acopf, acopf-paper, socp)."))
    solver = (inputs.manifest or {}).get("config", {}).get("acopf_solver", "auto")
    sec.add(
        Block(
            "note",
            text=(
                "AC OPF solver 'auto': where the SOCP relaxation's point is AC-feasible and its losses lie within 1e-6 of "
                "the relaxation's lower bound it is the certified AC optimum and IPOPT is not run; IPOPT solves the other "
                "steps. IPOPT's own failure rate on every step (the paper's question): opfbench run --acopf-solver ipopt."
                if solver == "auto"
                else "AC OPF solver 'ipopt': IPOPT solved every step of acopf and acopf-paper (the paper's question: how often "
                "does a nonlinear OPF solver fail?)."
            )
            + (
                " On a three-phase feeder IPOPT solves every step and, under 'auto', the SDP relaxation (sdp3) bounds every "
                "step of a short run and an evenly spread sample of a long one ('steps with a bound' counts them): a step is "
                "certified (by sdp3) where the optimum's losses lie within 1e-6 of that bound; the steps outside the sample are not. "
                "A step without a decision (no DER with usable Q: the night at k = 0) is bounded and certified at every step "
                "(by unique) where the power flow's point is proven the only one that meets the constraints: a contraction of "
                "the network's equations over the band (opfbench.formulations.unique_point); the SDP is not solved there."
                if inputs.summary is not None and "max_vuf_pct" in inputs.summary and inputs.summary["max_vuf_pct"].notna().any()
                else ""
            ),
        )
    )
    sec.add(table(conv, "Steps per status"))
    sec.add(
        table(
            tables.failure_reasons(inputs.steps, inputs.kinds()), "Steps not ok: status, solver return status and fallback used"
        )
    )
    sec.add(
        table(
            tables.solver_stats(inputs.steps, inputs.kinds()),
            "Solver iterations and solve times (ms): IPOPT for acopf/acopf-paper (0 iterations where the SOCP certified the step), Clarabel for socp",
        )
    )
    sec.blocks += _plots(plots.solve_times(inputs.steps))
    if inputs.summary is not None:
        setup = tables.paper_setup(inputs.summary, inputs.steps)
        sec.add(Block("heading", text="The paper's OPF setup (acopf-paper)"))
        if setup.empty:
            sec.add(
                Block(
                    "note",
                    text="The run has no acopf-paper configuration: run opfbench run with the default "
                    "strategies (or --strategies ... acopf-paper).",
                )
            )
        else:
            sec.add(
                Block(
                    "note",
                    text="acopf-paper: the slack may not export and a failed solve falls back to no action, "
                    "as in the paper; its energy beside our AC OPF (fallback chain) and LFMA.",
                )
            )
            sec.add(table(setup))
    return sec


def _run_meta(folder: object, m: dict) -> Block:
    """A finished run's folder, command, period, wall time and peak memory (its manifest)."""
    period, timings = m.get("period", {}), m.get("timings") or {}
    return Block(
        "meta",
        items=[
            ("run folder", f"{folder} (created {m.get('created_utc')}, opfbench {m.get('opfbench_version')})"),
            ("command", " ".join(str(a) for a in m.get("command") or [])),
            (
                "period",
                f"{period.get('start')} → {period.get('end')}, {period.get('steps')} steps of "
                f"{m.get('config', {}).get('step_minutes')} min; {len(m.get('tasks', []))} tasks",
            ),
            (
                "wall time",
                f"{_seconds(timings.get('wall_s'))} on {timings.get('workers')} worker process(es) "
                f"({(m.get('machine') or {}).get('cores')} cores)",
            ),
            (
                "peak memory",
                f"{timings.get('peak_rss_mb', float('nan')):.0f} MB (main process), "
                f"{timings.get('worker_peak_rss_mb', float('nan')):.0f} MB (largest worker process)",
            ),
        ],
    )


def year(inputs: Inputs, price: tuple[float, str, str]) -> Section:
    sec = Section(
        "year",
        "A year (2016 at 15 min)",
        "The whole grid over the year 2016 at SimBench's native 15 min: energy per strategy and k, savings vs "
        "no action, and what the run cost (wall time, peak memory).",
    )
    if (inputs.manifest or {}).get("config", {}).get("period") == "year":
        return sec.add(Block("note", text="This run is the year run: the sections above show it."))
    if inputs.year_summary is None or inputs.year_manifest is None:
        return sec.add(*_missing(inputs, "year run"))
    s = inputs.year_summary
    sec.add(_run_meta(inputs.year_dir, inputs.year_manifest))
    sec.blocks += _energy_tables(s, price, " over the year")
    kinds = tables.Kinds.of(s["strategy"], inputs.year_manifest.get("strategies"))
    sec.add(table(tables.convergence_summary(s, kinds), "Steps not ok over the year per formulation and k (all night modes)"))
    sec.blocks += _plots(plots.energy_vs_k(s, "year-energy-k", " over the year"))
    return sec


def field_year(inputs: Inputs, price: tuple[float, str, str]) -> Section:
    """The committed year on real grids (docs/field-year): every strategy on SimBench's
    1-MV-rural and 1-LV-rural3 with their own profiles — the leaderboard per night mode,
    the energies, the share of steps whose optimum is certified, what the run cost."""
    sec = Section(
        "field-year",
        "Real grids over a year (SimBench, 2016 at 15 min)",
        "Every strategy on SimBench's 1-MV-rural (102 generators) and 1-LV-rural3 over 2016 on the grids' own "
        "per-load and per-generator profiles, k ∈ {0, 0.4}, PV connected and disconnected at night (a committed "
        "run, docs/field-year): the leaderboard at equal compliance, the frontier of losses against compliance, the "
        "energies, how many steps' optimum is certified, and what the run cost. " + tables.SHARES,
    )
    if inputs.field_summary is None or inputs.field_manifest is None:
        return sec.add(*_missing(inputs, "real grids' year run"))
    s = inputs.field_summary
    sec.add(_run_meta("docs/field-year", inputs.field_manifest))
    if not tables.at_equal_compliance(s):
        sec.add(Block("note", text=BEFORE_FRONTIER))
    for mode in ("connected", "disconnected"):
        board = tables.leaderboard(s, night_mode=mode)
        if board.empty:
            continue
        sec.blocks += _share_notes(s, mode)
        sec.add(
            table(_shown(board), f"Leaderboard over the year, PV {mode} at night (rank 1 = smallest gap at equal compliance)")
        )
    if inputs.field_frontier is not None:
        sec.add(table(tables.frontier_table(inputs.field_frontier), "The frontier over the year (PV connected at night)"))
    sec.blocks += _plots(plots.frontier_vs_compliance(tables.leaderboard(s), inputs.field_frontier, " over the year"))
    kinds = tables.Kinds.of(s["strategy"], inputs.field_manifest.get("strategies"))
    sec.add(table(tables.convergence_summary(s, kinds), "Steps not ok and certified optima over the year per formulation and k"))
    sec.blocks += _energy_tables(s, price, " over the year")
    return sec


def night(inputs: Inputs) -> Section:
    sec = Section(
        "night",
        "Night hours",
        "PV inverters connected vs disconnected at night, and connected-q: connected with the S-limited "
        "capability at night (Q without the power-factor limit, 'Q at night'). Reduction % = "
        "1 − E(mode)/E(disconnected).",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    s = inputs.summary
    if "connected-q" not in set(s["night_mode"]):
        sec.add(
            Block(
                "note",
                text="The run has no connected-q night mode: run opfbench run --night-modes connected disconnected connected-q.",
            )
        )
    k = float(s["k"].min())
    sec.add(Block("heading", text=f"The paper's night-hour table beside ours (k = {k:g}, forecast off)"))
    sec.add(
        Block(
            "note",
            text="Paper Table III (SYSLAB data, 20 August 2019); the paper does not state k. "
            "acopf = our AC OPF (fallback chain).",
        )
    )
    sec.add(table(tables.night_vs_paper(s, k)))
    sec.add(table(tables.night(s), "Energy (kWh) per night mode, every strategy and k"))
    sec.blocks += _plots(plots.night_bars(s))
    return sec


def gap(inputs: Inputs) -> Section:
    sec = Section(
        "gap",
        "Optimality gap",
        "Each strategy's energy against the SOCP relaxation's lower bound (slack may export; certified: "
        "no AC-feasible setpoints can lose less), summed over the same steps: gap kWh and % of the bound.",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    s = inputs.summary
    sec.add(
        table(
            tables.energy_pivot(s[s["forecast"] == "off"], tables.REFERENCE_NIGHT, "gap_pct"),
            "Gap to the bound (%), PV connected at night, forecast off",
        )
    )
    sec.add(table(tables.gap(s), "Gap per configuration", collapse_over=0))
    sec.blocks += _plots(plots.gap_vs_k(s))
    return sec


def voltage(inputs: Inputs) -> Section:
    sec = Section(
        "voltage",
        "Voltage compliance",
        "Steps outside the case's voltage limits and the extreme voltages per strategy (over every k, night "
        "mode and forecast); Algorithm 3's capability excursions (setpoints above the inverter's capability at "
        "the current P, when the forecast P gives a larger limit).",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    limits = {name: (c.get("vmin_pu"), c.get("vmax_pu")) for name, c in ((inputs.manifest or {}).get("cases") or {}).items()}
    if limits:
        sec.add(Block("note", text="Limits: " + "; ".join(f"{n} [{lo}, {hi}] p.u." for n, (lo, hi) in limits.items())))
    sec.blocks += _no_figure_note(inputs.summary)
    sec.add(table(tables.voltage(inputs.summary)))
    exc = tables.excursions(inputs.summary, inputs.kinds())
    if exc.empty:
        sec.add(Block("note", text="No forecast-aware configuration in the run (forecast off only)."))
    else:
        sec.add(table(exc, "Algorithm 3: steps with a capability excursion and the largest excursion (MVAr)"))
    if inputs.steps is not None:
        sec.blocks += _plots(plots.voltage_envelope(inputs.steps, limits))
    return sec


VUF_LIMIT_PCT = 2.0  # EN 50160: the 10-min VUF stays below 2 % (95 % of a week)


def unbalance(inputs: Inputs) -> Section:
    """What unbalance adds on three-phase feeders: the voltage unbalance factor per
    configuration and each feeder's per-phase voltage profile at its worst step."""
    sec = Section(
        "unbalance",
        "Unbalanced feeders: voltage profile and unbalance",
        f"On three-phase feeders every DER acts on its own phase voltage. The voltage unbalance factor VUF = "
        f"|V₂|/|V₁| (negative- over positive-sequence voltage) at every bus with three phases, worst per "
        f"configuration, and the minutes of steps whose worst VUF exceeds EN 50160's {VUF_LIMIT_PCT:g} %; then each "
        "feeder's voltage along it, phase by phase, at its worst-voltage step (OpenDSS's plot profile).",
    )
    if inputs.summary is None:
        return sec.add(*_missing(inputs, "summary.csv"))
    summary = inputs.summary
    three = summary[summary["max_vuf_pct"].notna()] if "max_vuf_pct" in summary.columns else summary.iloc[:0]
    if three.empty:
        return sec.add(Block("note", text="No three-phase feeder in this run (balanced cases have no unbalance)."))
    keys = [c for c in ("case", "strategy", "k", "night_mode", "forecast") if c in three.columns]
    cols = keys + [c for c in ("max_vuf_pct", "vuf_min", "vmin_pu", "vmax_pu", "voltage_violation_steps") if c in three.columns]
    worst = three.sort_values("max_vuf_pct", ascending=False)[cols]
    above = int((three["vuf_min"] > 0).sum()) if "vuf_min" in three.columns else 0
    sec.add(
        Block(
            "note",
            text=f"Worst VUF {worst['max_vuf_pct'].iloc[0]:.3f} % ({worst['case'].iloc[0]}, {worst['strategy'].iloc[0]}); "
            f"{above} of {len(three)} configurations spend minutes above {VUF_LIMIT_PCT:g} %.",
        )
    )
    sec.add(table(worst, "Voltage unbalance per configuration (worst first)"))
    if inputs.steps is None or inputs.manifest is None:
        return sec.add(*_missing(inputs, "steps.parquet", "manifest.json"))
    from opfbench.report.profiles import profile

    for i, case in enumerate(sorted(three["case"].astype(str).unique())):
        found = profile(inputs.manifest, inputs.steps, case)
        if found is None:
            sec.add(Block("note", text=f"{case}: no converged no-action step to draw its profile at."))
        else:
            sec.blocks += _plots([plots.voltage_profile(found, i)])
    return sec


def forecasting(inputs: Inputs) -> Section:
    source = inputs.forecast_dir
    sec = Section(
        "forecasting",
        "Forecasting",
        "One-step-ahead forecast metrics beside the paper's Table I (SYSLAB 2019, 5-min data; our data and "
        "resolution differ, so only the ranking is comparable). MSE on min-max scaled data, MAPE on samples "
        "above a fraction of the rating (see the forecast run).",
    )
    if not inputs.forecast:
        return sec.add(*_missing(inputs, "forecast"))
    sec.add(Block("note", text=f"From {source}: " + ", ".join(f"forecast_{d}.json" for d in inputs.forecast)))
    sec.add(table(tables.forecast_metrics(inputs.forecast)))
    return sec


def fault(inputs: Inputs) -> Section:
    sec = Section(
        "fault",
        "Fault ride-through",
        "Voltage recovery time at the faulted bus (fault inception until |V| stays ≥ 0.9 p.u.) per fault bus, "
        "strategy, k and forecast, and the time each strategy adds over no action.",
    )
    if inputs.fault is None:
        return sec.add(*_missing(inputs, "fault.parquet"))
    rec = tables.recovery(inputs.fault)
    if rec.empty:
        return sec.add(Block("note", text=f"{inputs.fault_dir}/fault.parquet has no row at a faulted bus (faulted = true)."))
    variants = sorted(rec["variant"].unique())
    variant = "reference" if "reference" in variants else variants[0]
    sec.add(table(tables.recovery_pivot(rec, variant), f"Recovery time (ms) at the faulted bus, model variant {variant}"))
    sec.add(table(tables.sensitivity(rec), "Sensitivity to the source / motor model variants"))
    sec.add(table(rec, "Every simulation (faulted bus)", collapse_over=0))
    sec.blocks += _plots(plots.recovery_per_bus(rec)) + _plots(plots.recovery_vs_k(rec))
    if inputs.traces is not None:
        sec.blocks += _plots(plots.fault_traces(inputs.traces))
    else:
        sec.blocks += _missing(inputs, "traces.parquet")
    return sec


def paper_claims(inputs: Inputs) -> Section:
    sec = Section(
        "claims",
        "The paper's claims",
        "Each claim with the paper's figure, ours, and a verdict computed from the run's tables (the sections below show them).",
    )
    return sec.add(Block("claims", claims=claims(inputs)))


Price = tuple[float, str, str]  # energy price per kWh, currency, source
Builder = Callable[[Inputs, Price], Section]


def _unpriced(build: Callable[[Inputs], Section]) -> Builder:
    """A builder that does not use the price, called like those that do."""
    return lambda inputs, _price: build(inputs)


SECTIONS: tuple[tuple[str, str, Builder], ...] = (
    ("local", "How close can a local rule get", _unpriced(how_close)),
    ("claims", "The paper's claims", _unpriced(paper_claims)),
    ("metadata", "Run metadata", metadata),
    ("losses", "Losses and savings", losses),
    ("grids", "Leaderboard per case", _unpriced(grids)),
    ("convergence", "Convergence of the formulations", _unpriced(convergence)),
    ("year", "A year (2016 at 15 min)", year),
    ("field-year", "Real grids over a year (SimBench, 2016 at 15 min)", field_year),
    ("night", "Night hours", _unpriced(night)),
    ("gap", "Optimality gap", _unpriced(gap)),
    ("voltage", "Voltage compliance", _unpriced(voltage)),
    ("unbalance", "Unbalanced feeders: voltage profile and unbalance", _unpriced(unbalance)),
    ("forecasting", "Forecasting", _unpriced(forecasting)),
    ("fault", "Fault ride-through", _unpriced(fault)),
)
"""(id, title, builder) in page order."""
FAILED = "This section could not be built from its input files"


def all_sections(inputs: Inputs, price: tuple[float, str, str]) -> list[Section]:
    """Every section; one whose input files are inconsistent (a contract broken by the
    writer) shows the error instead of stopping the report."""
    out = []
    for sid, title, build in SECTIONS:
        try:
            out.append(build(inputs, price))
        except (KeyError, ValueError, IndexError, TypeError) as exc:
            out.append(Section(sid, title, blocks=[Block("error", text=f"{FAILED}: {type(exc).__name__}: {exc}")]))
    return out


def price_of(inputs: Inputs, price: float | None) -> tuple[float, str, str]:
    """(price per kWh, currency, source): `price` if given, else the manifest's, else the default."""
    cfg = (inputs.manifest or {}).get("config", {})
    currency = cfg.get("currency") or DEFAULT_CURRENCY
    if price is not None:
        return float(price), currency, "given with --price"
    if cfg.get("price_per_kwh") is not None:
        return float(cfg["price_per_kwh"]), currency, str(cfg.get("price_source") or "the run's manifest")
    return DEFAULT_PRICE_PER_KWH, DEFAULT_CURRENCY, DEFAULT_PRICE_SOURCE
