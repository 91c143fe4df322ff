"""The report's Plotly figures. Each function returns a list of `Plot` (possibly empty when
its input lacks the data); `Plot.json` is the figure as JSON safe to embed in a
<script type="application/json"> element (<, > and & escaped as \\u003c, \\u003e, \\u0026).

Strings from input (case, strategy, model names) are HTML-escaped before they reach
Plotly, whose text rendering understands a few HTML tags."""

from __future__ import annotations

import json
import re
import textwrap
from dataclasses import dataclass
from functools import lru_cache
from html import escape

import numpy as np
import pandas as pd
import plotly.graph_objects as go
import plotly.io as pio
from plotly.subplots import make_subplots

from opfbench.registry.references import BASELINE
from opfbench.report.inputs import TRACE_BUS
from opfbench.report.profiles import Profile
from opfbench.report.tables import REFERENCE_NIGHT, order

MAX_POINTS = 1440
"""Per-step traces are bin-averaged to at most this many points (a day at 1 min)."""
HEIGHT = 380
TITLE_CHARS = 90  # a longer title line runs under Plotly's toolbar (top right): wrapped at spaces
TITLE_LINE_PX = 22  # the top margin each further title line adds


@dataclass(frozen=True)
class Plot:
    id: str
    title: str
    json: str


def script_json(text: str) -> str:
    """JSON text safe to embed in a <script type="application/json"> element (<, > and &
    escaped as \\u003c, \\u003e, \\u0026)."""
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


@lru_cache(maxsize=1)
def plot_template() -> str:
    """Plotly's "plotly_white" template as JSON, embedded once per page and given to every
    figure there (the figures carry none: copying it into each is slow)."""
    return script_json(json.dumps(pio.templates["plotly_white"].to_plotly_json()))


def _figure() -> go.Figure:
    """A figure without a template: the page gives every figure one (`plot_template`)."""
    return go.Figure(layout={"template": "none"})


def _subplots(**options: object) -> go.Figure:
    return make_subplots(figure=_figure(), **options)


def wrapped_title(title: str) -> tuple[str, int]:
    """`title` HTML-escaped with its lines broken at spaces to at most TITLE_CHARS
    characters (Plotly's `<br>`), and the number of lines."""
    lines = textwrap.wrap(title, TITLE_CHARS) or [title]
    return "<br>".join(escape(line) for line in lines), len(lines)


def plot_json(pid: str, title: str, fig: go.Figure, xtitle: str, ytitle: str, height: int = HEIGHT) -> Plot:
    text, lines = wrapped_title(title)
    top = 50 + TITLE_LINE_PX * (lines - 1)
    fig.update_layout(height=height + top - 50, title=text, margin=dict(l=60, r=20, t=top, b=50), legend=dict(orientation="v"))
    if xtitle:
        fig.update_xaxes(title_text=xtitle)
    if ytitle:
        fig.update_yaxes(title_text=ytitle)
    return Plot(pid, title, script_json(fig.to_json(engine="json")))


def _decimate(frame: pd.DataFrame, *values: str) -> pd.DataFrame:
    """Mean of each of `values` in at most MAX_POINTS equal bins of rows (rows sorted by
    time); the time as local wall-clock text, which is what plotly.js shows (it ignores
    zone offsets; formatted once here rather than per element by Plotly, which is slow on
    long traces)."""
    if len(frame) > MAX_POINTS:
        bins = np.arange(len(frame)) * MAX_POINTS // len(frame)
        frame = frame.groupby(bins).agg(time=("time", "first"), **{value: (value, "mean") for value in values})
    time = pd.DatetimeIndex(frame["time"])
    wall_clock = time.tz_localize(None) if time.tz is not None else time
    text = np.datetime_as_string(wall_clock.to_numpy(), unit="s")
    return pd.DataFrame({"time": text} | {value: frame[value].to_numpy() for value in values})


def _reference(frame: pd.DataFrame) -> tuple[pd.DataFrame, float]:
    """Rows of the reference setting: night connected (else the first mode), forecast off, smallest k."""
    modes = list(frame["night_mode"].unique())
    mode = REFERENCE_NIGHT if REFERENCE_NIGHT in modes else modes[0]
    sub = frame[(frame["night_mode"] == mode) & (frame["forecast"] == "off")]
    k = float(sub["k"].min()) if len(sub) else float("nan")
    return sub[np.isclose(sub["k"], k)], k


def _cases(frame: pd.DataFrame) -> list[str]:
    return sorted(str(case) for case in frame["case"].unique())


def _by_strategy(frame: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The rows of each strategy of `frame` (in their order), sorted by time."""
    return {str(name): rows.sort_values("time") for name, rows in frame.groupby("strategy", observed=True, sort=False)}


def losses_day(steps: pd.DataFrame) -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(steps)):
        sub, k = _reference(steps[steps["case"] == case])
        fig = _figure()
        rows = _by_strategy(sub)
        for strategy in order(sub[["strategy"]].drop_duplicates())["strategy"]:
            d = _decimate(rows[strategy], "losses_kw")
            fig.add_scatter(x=d["time"], y=d["losses_kw"], mode="lines", name=escape(strategy))
        out.append(
            plot_json(
                f"losses-day-{i}",
                f"{case}: losses through the day (k={k:g}, night connected, forecast off)",
                fig,
                "time",
                "losses (kW)",
            )
        )
    return out


def energy_vs_k(summary: pd.DataFrame, pid: str = "energy-k", period: str = "") -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(summary)):
        sub = summary[(summary["case"] == case) & (summary["night_mode"] == REFERENCE_NIGHT)]
        fig = _figure()
        for (strategy, forecast), grp in order(sub).groupby(["strategy", "forecast"], sort=False):
            grp = grp.sort_values("k")
            name = strategy if forecast == "off" else f"{strategy} (forecast {forecast})"
            fig.add_scatter(
                x=grp["k"],
                y=grp["energy_kwh"],
                mode="lines+markers",
                name=escape(name),
                line=dict(dash="solid" if forecast == "off" else "dot"),
            )
        out.append(
            plot_json(
                f"{pid}-{i}",
                f"{case}: energy losses vs reserve k{period} (night connected)",
                fig,
                "reserve coefficient k",
                "energy losses (kWh)",
            )
        )
    return out


def der_q_day(der_q: pd.DataFrame) -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(der_q)):
        sub, k = _reference(der_q[der_q["case"] == case])
        strategies = [s for s in order(sub[["strategy"]].drop_duplicates())["strategy"] if s != BASELINE]
        if not strategies:
            continue
        unit = "der" if "der" in sub.columns else "bus"  # a folder written before DER had names: one per bus
        units = sorted(sub[unit].unique())
        fig = _subplots(
            rows=len(strategies), cols=1, shared_xaxes=True, subplot_titles=[escape(s) for s in strategies], vertical_spacing=0.06
        )
        for row, strategy in enumerate(strategies, start=1):
            for der, grp in sub[sub["strategy"] == strategy].groupby(unit):
                d = _decimate(grp.sort_values("time"), "q_mvar")
                kind = escape(str(grp["kind"].iloc[0]))
                color = _COLORS[units.index(der) % len(_COLORS)]  # a DER keeps its colour in every panel
                bus = grp["bus"].iloc[0]
                fig.add_scatter(
                    x=d["time"],
                    y=d["q_mvar"],
                    mode="lines",
                    name=f"{escape(str(der))} (bus {bus})" if unit == "der" else f"bus {bus} ({kind})",
                    line=dict(color=color),
                    legendgroup=escape(str(der)),
                    showlegend=row == 1,
                    row=row,
                    col=1,
                )
            fig.update_yaxes(title_text="Q (MVAr)", row=row, col=1)
        out.append(
            plot_json(
                f"der-q-{i}",
                f"{case}: DER Q setpoints through the day (k={k:g}, night connected, forecast off)",
                fig,
                "",
                "",
                height=max(HEIGHT, 220 * len(strategies)),
            )
        )
    return out


def voltage_envelope(steps: pd.DataFrame, limits: dict[str, tuple[float, float]]) -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(steps)):
        sub, k = _reference(steps[steps["case"] == case])
        fig = _figure()
        rows = _by_strategy(sub)
        for j, strategy in enumerate(order(sub[["strategy"]].drop_duplicates())["strategy"]):
            env = _decimate(rows[strategy], "vmin_pu", "vmax_pu")
            color = _COLORS[j % len(_COLORS)]
            fig.add_scatter(
                x=env["time"],
                y=env["vmin_pu"],
                mode="lines",
                name=f"{escape(strategy)} min",
                line=dict(color=color),
                legendgroup=escape(strategy),
            )
            fig.add_scatter(
                x=env["time"],
                y=env["vmax_pu"],
                mode="lines",
                name=f"{escape(strategy)} max",
                line=dict(color=color, dash="dot"),
                legendgroup=escape(strategy),
            )
        if case in limits:
            for v in limits[case]:
                fig.add_hline(y=v, line=dict(color="#b00", dash="dash", width=1))
        out.append(
            plot_json(
                f"voltage-{i}",
                f"{case}: voltage envelope through the day (k={k:g}, night connected, "
                "forecast off; dashed red: the case's limits)",
                fig,
                "time",
                "|V| (p.u.)",
            )
        )
    return out


def _lines_over_k(fig: go.Figure, frame: pd.DataFrame, x: str, y: str, hover_columns: list[str], hover: str) -> None:
    """One trace per strategy of `frame` (registry order), its points ordered by k."""
    for strategy, grp in order(frame).groupby("strategy", sort=False):
        grp = grp.sort_values("k")
        fig.add_scatter(
            x=grp[x],
            y=grp[y],
            mode="lines+markers",
            name=escape(strategy),
            customdata=grp[hover_columns].to_numpy(),
            hovertemplate=hover,
        )


def gap_vs_k(summary: pd.DataFrame) -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(summary)):
        sub = summary[(summary["case"] == case) & (summary["night_mode"] == REFERENCE_NIGHT) & (summary["forecast"] == "off")]
        sub = sub.dropna(subset=["gap_pct"])
        if sub.empty:
            continue
        fig = _figure()
        _lines_over_k(fig, sub, "k", "gap_pct", ["gap_kwh"], "k=%{x}<br>gap %{y:.2f} %<br>%{customdata[0]:.2f} kWh")
        out.append(
            plot_json(
                f"gap-{i}",
                f"{case}: gap to the SOCP lower bound (night connected, forecast off)",
                fig,
                "reserve coefficient k",
                "gap to the bound (%)",
            )
        )
    return out


SHARE_AXES = (
    ("recovery_added_ms", "fault recovery time added over no action (ms, mean over the fault buses)", "%{x:.0f} ms added"),
)
"""What a share is plotted against, when the case has it (compliance: `frontier_vs_compliance`)."""


def share_column(board: pd.DataFrame) -> tuple[str, str]:
    """The share a board's figures show and its name: at equal compliance where the board
    has it, else (a run written before the frontier) the loss-only share, said so."""
    if "share_eq_pct" in board and board["share_eq_pct"].notna().any():
        return "share_eq_pct", "share at equal compliance"
    return "loss_only_share_pct", "loss-only share of the AC OPF's reduction"


def share_vs_costs(board: pd.DataFrame) -> list[Plot]:
    """Per case: each strategy's share (`share_column`, one point per k) against the fault
    recovery time it adds, when a fault study gave one; with none, the share against k (a
    `tables.leaderboard`)."""
    out: list[Plot] = []
    column, what = share_column(board)
    for i, case in enumerate(_cases(board)):
        sub = board[board["case"] == case].dropna(subset=[column])
        axes = [(c, title, text) for c, title, text in SHARE_AXES if c in sub and sub[c].notna().any()] or [
            ("k", "reserve coefficient k", "k=%{x}")
        ]
        for x, title, text in axes:
            fig = _figure()
            hover = f"k=%{{customdata[0]}}<br>%{{y:.1f}} % ({what})<br>{text}<br>%{{customdata[1]:.2f}} kWh"
            _lines_over_k(fig, sub.dropna(subset=[x]), x, column, ["k", "energy_kwh"], hover)
            out.append(
                plot_json(
                    f"share-{x.replace('_', '-')}-{i}",
                    f"{case}: {what} vs {title.split(' (')[0]} (one point per k, night connected, forecast off)",
                    fig,
                    title,
                    f"{what} (%)",
                )
            )
    return out


def frontier_vs_compliance(board: pd.DataFrame, frontier: pd.DataFrame | None, name: str = "") -> list[Plot]:
    """Per case and k (forecast off, PV connected at night): losses plus curtailed energy
    against the worst excursion beyond the voltage band — the frontier as a line (the AC
    OPF with the band widened by ε: on (ε_i−1, ε_i] its energy at ε_i, the reference of
    any point whose excursions stay within ε_i, so no point of a configuration that does
    not curtail lies below it) and each rule and formulation a point (`tables.leaderboard`'s
    rows; its minutes outside, gap and share in the hover). A configuration that curtails
    (◆) is compared, where it curtails, with the optimum that may curtail: it could lie
    below the line by what curtailing there saves. `name` tells one run's figures from
    another's."""
    if frontier is None or frontier.empty or board.empty:
        return []
    out: list[Plot] = []
    front = frontier[(frontier["night_mode"] == REFERENCE_NIGHT) & ~frontier["curtail"].astype(bool)]
    for i, ((case, k), grp) in enumerate(board.groupby(["case", "k"], sort=False)):
        line = front[(front["case"] == case) & np.isclose(front["k"], k)].dropna(subset=["energy_kwh"]).sort_values("eps_pu")
        points = grp.dropna(subset=["cost_kwh", "max_violation_pu"])
        if line.empty or points.empty:
            continue
        finite = line[np.isfinite(line["eps_pu"])]
        right = 1.15 * max(float(finite["eps_pu"].max()), float(points["max_violation_pu"].max()), 1e-3)
        fig = _figure()
        fig.add_scatter(
            x=[e if np.isfinite(e) else right for e in line["eps_pu"]],
            y=list(line["energy_kwh"]),
            mode="lines+markers",
            line=dict(shape="vh", color="#000"),
            name="frontier: AC OPF, band widened by ε",
            customdata=[f"{e:g}" if np.isfinite(e) else "∞ (physical limits)" for e in line["eps_pu"]],
            hovertemplate="ε = %{customdata} p.u.<br>%{y:.2f} kWh<extra>frontier</extra>",
        )
        for strategy, row in order(points).set_index("strategy").iterrows():
            cut = bool(row.get("frontier_curtails", False) is True)
            fig.add_scatter(
                x=[row["max_violation_pu"]],
                y=[row["cost_kwh"]],
                mode="markers",
                marker=dict(symbol="diamond" if cut else "circle", size=9),
                name=escape(str(strategy)),
                customdata=[[row["voltage_violation_min"], row.get("gap_eq_kwh", np.nan), row.get("share_eq_pct", np.nan)]],
                hovertemplate="worst excursion %{x:.4f} p.u., %{customdata[0]:.0f} min outside<br>"
                "%{y:.2f} kWh; gap at equal compliance %{customdata[1]:.2f} kWh, share %{customdata[2]:.1f} %",
            )
        out.append(
            plot_json(
                f"frontier-{re.sub(r'[^a-z0-9]+', '-', name.lower()).strip('-')}-{i}".replace("--", "-"),
                f"{case}{name}, k={k:g}: losses + curtailed energy against the worst excursion beyond the voltage "
                "band (PV connected at night, forecast off); the line is the frontier, on or below every point of a "
                "rule that does not curtail (◆: one that curtails, compared where it does with the optimum that may)",
                fig,
                "worst excursion beyond the voltage band (p.u.)",
                "losses + curtailed energy (kWh)",
                height=460,
            )
        )
    return out


def night_bars(summary: pd.DataFrame) -> list[Plot]:
    out = []
    for i, case in enumerate(_cases(summary)):
        sub = summary[(summary["case"] == case) & (summary["forecast"] == "off")]
        k = float(sub["k"].min())
        sub = order(sub[np.isclose(sub["k"], k)])
        fig = _figure()
        for mode, grp in sub.groupby("night_mode", sort=True):
            fig.add_bar(x=[escape(s) for s in grp["strategy"]], y=grp["energy_kwh"], name=f"PV {escape(mode)} at night")
        fig.update_layout(barmode="group")
        out.append(
            plot_json(
                f"night-{i}",
                f"{case}: energy losses per night mode (k={k:g}, forecast off)",
                fig,
                "strategy",
                "energy losses (kWh)",
            )
        )
    return out


def solve_times(steps: pd.DataFrame) -> list[Plot]:
    sub = steps.dropna(subset=["solver_ms"])
    if sub.empty:
        return []
    fig = _figure()
    for (case, strategy), grp in order(sub).groupby(["case", "strategy"], sort=False):
        # the box's statistics computed here, not every step's time shipped to the page
        ms = grp["solver_ms"].to_numpy(dtype=float)
        q1, median, q3 = np.percentile(ms, [25, 50, 75])
        whisker = 1.5 * (q3 - q1)
        fig.add_box(
            name=escape(f"{strategy} ({case})"),
            q1=[q1],
            median=[median],
            q3=[q3],
            lowerfence=[ms[ms >= q1 - whisker].min()],
            upperfence=[ms[ms <= q3 + whisker].max()],
            x=[escape(f"{strategy} ({case})")],
        )
    return [plot_json("solve-times", "Solve time per step and formulation", fig, "", "solve time (ms)")]


def recovery_per_bus(rec: pd.DataFrame) -> list[Plot]:
    sub = rec[rec["variant"] == "reference"] if (rec["variant"] == "reference").any() else rec
    if sub.empty:
        return []
    k = float(sub["k"].min())
    sub = order(sub[np.isclose(sub["k"], k) & (sub["forecast"] == "off")])
    fig = _figure()
    for strategy, grp in sub.groupby("strategy", sort=False):
        fig.add_bar(
            x=[escape(f"{c} bus {b}") for c, b in zip(grp["case"], grp["fault_bus"], strict=True)],
            y=grp["recovery_ms"],
            name=escape(strategy),
        )
    fig.update_layout(barmode="group")
    return [
        plot_json(
            "recovery-bus",
            f"Recovery time per fault bus (k={k:g}, forecast off, reference model)",
            fig,
            "fault bus",
            "recovery time (ms)",
        )
    ]


def recovery_vs_k(rec: pd.DataFrame) -> list[Plot]:
    sub = rec[rec["variant"] == "reference"] if (rec["variant"] == "reference").any() else rec
    sub = sub[sub["forecast"] == "off"]
    if sub.empty:
        return []
    fig = _figure()
    for (case, bus, strategy), grp in order(sub).groupby(["case", "fault_bus", "strategy"], sort=False):
        grp = grp.sort_values("k")
        fig.add_scatter(
            x=grp["k"],
            y=grp["recovery_ms"],
            mode="lines+markers",
            name=escape(f"{strategy}, {case} fault at {bus}"),
            legendgroup=escape(strategy),
        )
    return [
        plot_json(
            "recovery-k",
            "Recovery time vs reserve k (forecast off, reference model)",
            fig,
            "reserve coefficient k",
            "recovery time (ms)",
        )
    ]


def fault_traces(traces: pd.DataFrame, bus: int = TRACE_BUS) -> list[Plot]:
    """|V| and Q at `bus` (the paper's DFIG) through the fault, per strategy: the fault at
    `bus` when simulated, else the first fault bus; smallest k, forecast off, reference model."""
    sub = traces[(traces["bus"] == bus) & (traces["forecast"] == "off")]
    if (sub["variant"] == "reference").any():
        sub = sub[sub["variant"] == "reference"]
    if sub.empty:
        return []
    fault_bus = bus if (sub["fault_bus"] == bus).any() else sorted(sub["fault_bus"].unique())[0]
    sub = sub[sub["fault_bus"] == fault_bus]
    case = sorted(sub["case"].astype(str).unique())[0]
    sub = sub[sub["case"] == case]
    k = float(sub["k"].min())
    sub = sub[np.isclose(sub["k"], k)]
    fig = _subplots(rows=2, cols=1, shared_xaxes=True, subplot_titles=("|V| (p.u.)", "Q (MVAr)"), vertical_spacing=0.1)
    for j, (strategy, grp) in enumerate(order(sub).groupby("strategy", sort=False)):
        grp = grp.sort_values("t_s")
        color = _COLORS[j % len(_COLORS)]
        fig.add_scatter(
            x=grp["t_s"],
            y=grp["v_pu"],
            mode="lines",
            name=escape(strategy),
            line=dict(color=color),
            legendgroup=escape(strategy),
            row=1,
            col=1,
        )
        fig.add_scatter(
            x=grp["t_s"],
            y=grp["q_mvar"],
            mode="lines",
            name=escape(strategy),
            line=dict(color=color),
            legendgroup=escape(strategy),
            showlegend=False,
            row=2,
            col=1,
        )
    fig.update_xaxes(title_text="time (s)", row=2, col=1)
    return [
        plot_json(
            "fault-traces",
            f"{case}: voltage and Q at bus {bus}, fault at bus {fault_bus} (k={k:g}, forecast off)",
            fig,
            "",
            "",
            height=2 * HEIGHT,
        )
    ]


_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


SHARE_FLOOR_PCT = -150.0
"""The headline figure's lowest share shown: a rule far worse than no action (where the OPF
saves little, shares run to −3000 %) would flatten every other bar."""


def _short(label: str) -> str:
    """A configuration label without its training period (the run's one, said beside)."""
    return re.sub(r"(?<=[:,])train=[^,]*,?", "", label).rstrip(":,")


def how_close(table: pd.DataFrame, name: str = "") -> list[Plot]:
    """The share at equal compliance each local rule reaches (the loss-only share for a run
    written before the frontier, said so), training and test period side by side, per
    case, at the smallest k (a `tables.how_close`); `name` tells one run's figure from
    another's."""
    eq = table["test_share_eq_pct"].notna().any() if not table.empty else False
    train, test = ("train_share_eq_pct", "test_share_eq_pct") if eq else ("train_loss_only_share_pct", "test_loss_only_share_pct")
    what = "at equal compliance" if eq else "of the AC OPF's loss reduction, loss-only"
    if table.empty or test not in table or table[test].isna().all():
        return []
    k = float(table["k"].min())
    sub = table[np.isclose(table["k"], k)]
    cases = [escape(str(c)) for c in sub["case"]]
    names = [escape(_short(str(s))) for s in sub["strategy"]]
    fig = _figure()
    for column, side in ((train, "training period"), (test, "test period")):
        if column in sub and sub[column].notna().any():
            fig.add_bar(
                x=[cases, names],
                y=sub[column],
                name=side,
                hovertemplate="%{x}<br>share %{y:.1f} % (" + what + ")<extra>" + side + "</extra>",
            )
    fig.update_layout(barmode="group")
    shown = sub[[c for c in (train, test) if c in sub]].to_numpy(dtype=float)
    cut = f"; axis cut at {SHARE_FLOOR_PCT:g} %, the table has every value" if np.nanmin(shown) < SHARE_FLOOR_PCT else ""
    if cut:
        fig.update_yaxes(range=[SHARE_FLOOR_PCT, max(110.0, float(np.nanmax(shown)) + 5)])
    return [
        plot_json(
            "how-close" + re.sub(r"[^a-z0-9]+", "-", name.lower()).rstrip("-"),
            f"How close can a local rule get{name}: share {what} (k={k:g}, PV connected at night, forecast off{cut})",
            fig,
            "",
            f"share {what} (%)",
            height=460,
        )
    ]


_PHASE_COLORS = {1: "#000000", 2: "#d62728", 3: "#1f77b4"}  # OpenDSS's plot profile: phase A black, B red, C blue


def voltage_profile(profile: Profile, index: int) -> Plot:
    """A three-phase feeder's |V| against distance from the source, one line per phase
    (each segment from a bus's upstream bus to it), the band dashed (`report.profiles`)."""
    fig = _figure()
    for phase, (xs, ys) in profile.segments.items():
        if xs:
            fig.add_scatter(
                x=xs,
                y=ys,
                mode="lines+markers",
                name=f"phase {phase}",
                line=dict(color=_PHASE_COLORS[phase], width=1),
                marker=dict(size=3),
            )
    for v in profile.band:
        fig.add_hline(y=v, line=dict(color="#b00", dash="dash", width=1))
    when = profile.time.strftime("%Y-%m-%d %H:%M")
    return plot_json(
        f"profile-{index}",
        f"{profile.case}: voltage profile at the worst-voltage step ({when}, no action; |V| {profile.vmin:.4f}–{profile.vmax:.4f} p.u.)",
        fig,
        "distance from the source (km)",
        "|V| (p.u. of the node's base)",
    )
