"""HTML report section of a forecast run: metrics beside paper Table I, one test day plot.

`forecast_section(result)` returns an HTML fragment (for embedding in a larger report);
`forecast_page(result)` wraps it into a self-contained page (inline CSS, the plot as a
base64 PNG — no external resources).
"""

from __future__ import annotations

import base64
import io
import math
from html import escape

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from opfbench.forecasting.experiment import ComparisonResult  # noqa: E402

PAPER_TABLE: dict[str, dict[str, tuple[float, float]]] = {
    "pv": {
        "arima": (0.078133, 9.266340),
        "lstm": (0.023628, 9.036990),
        "cnn-lstm": (0.031563, 8.588293),
        "wavelet-cnn-lstm": (0.009207, 7.088293),
    },
    "wind": {
        "arima": (0.058891, 17.60283),
        "lstm": (0.045361, 6.635954),
        "cnn-lstm": (0.039862, 6.253098),
        "wavelet-cnn-lstm": (0.013768, 5.785152),
    },
}
"""Paper Table I: (MSE on scaled data, MAPE %) per dataset and model (SYSLAB 2019, 5-min)."""

_CSS = """
body{font-family:system-ui,sans-serif;max-width:70rem;margin:2rem auto;padding:0 1rem;color:#222}
table{border-collapse:collapse;margin:1rem 0}th,td{border:1px solid #bbb;padding:.3rem .6rem;text-align:right}
th:first-child,td:first-child{text-align:left}thead th{background:#eee}.paper{background:#f6f6ff}
img{max-width:100%}.note{color:#555;font-size:.9rem}
"""


def forecast_section(result: ComparisonResult) -> str:
    """HTML fragment: run description, metrics table with paper values, test-day plot."""
    s = result.settings
    f = result.forecasts
    rows = "\n".join(_table_row(result.dataset, name, run.as_dict()) for name, run in result.runs.items())
    return f"""<section class="forecast" id="forecast-{escape(result.dataset)}">
<h2>One-step-ahead forecast: {escape(result.dataset.upper())}</h2>
<p>Training {escape(str(result.train_range[0]))} – {escape(str(result.train_range[1]))};
test {escape(str(f.index[0]))} – {escape(str(f.index[-1]))} ({len(f)} steps of {_step_text(f.index)}).
Rating {result.rating_kw:g} kW. Input window {s.window} steps; networks trained {s.epochs} epochs of
{escape(str(s.windows_per_epoch or "all"))} windows (batch {s.batch_size}, Adam {s.learning_rate:g}, best epoch on the
last {s.train_config(result.seed).val_fraction:.0%} of the training windows); ARIMA order by AIC on the last {s.arima_fit_samples} training steps;
wavelet {escape(s.wavelet)}, {s.wavelet_level} levels, applied per input window. Seed {result.seed}.</p>
<table>
<thead><tr><th>model</th><th>MSE (scaled)</th><th>MAPE %</th><th>MAE kW</th><th>RMSE kW</th>
<th>skill vs persistence</th><th>fit s</th><th class="paper">paper MSE</th><th class="paper">paper MAPE %</th></tr></thead>
<tbody>
{rows}
</tbody>
</table>
<p class="note">MSE on the series min-max scaled with the training range of the power; MAPE over test samples
whose actual power exceeds {s.mape_threshold:.0%} of the rating; skill = 1 − RMSE/RMSE<sub>persistence</sub>.
{_weather_text(result.weather_lag)}
Paper values: SYSLAB (DTU) 2019 data at 5-min resolution, with a softmax output layer; our data and
resolution differ, so only the ranking is comparable.</p>
<img alt="{escape(result.dataset)} test day: actual vs forecasts" src="data:image/png;base64,{_day_plot(result)}">
</section>"""


def forecast_page(result: ComparisonResult) -> str:
    """Self-contained HTML page with `forecast_section(result)`."""
    return html_page(f"opfbench forecast — {result.dataset}", forecast_section(result))


def html_page(title: str, body: str) -> str:
    """Minimal standalone HTML5 page around `body` (inline CSS only)."""
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{escape(title)}</title>'
        f"<style>{_CSS}</style></head>\n<body>\n<h1>{escape(title)}</h1>\n{body}\n</body></html>\n"
    )


def plot_day(forecasts: pd.DataFrame) -> pd.DataFrame:
    """The test day shown: 24 h from the first midnight (index time zone) of the test part
    when a full day follows it, else the first 24 h of the test part."""
    index = forecasts.index
    midnight = index[0].ceil("D")
    start = midnight if midnight + pd.Timedelta(days=1) <= index[-1] + (index[1] - index[0]) else index[0]
    return forecasts[(index >= start) & (index < start + pd.Timedelta(days=1))]


def _table_row(dataset: str, name: str, values: dict[str, object]) -> str:
    paper = PAPER_TABLE.get(dataset, {}).get(name)
    cells = [
        _fmt(values["mse_scaled"], ".5f"),
        _fmt(values["mape_pct"], ".2f"),
        _fmt(values["mae_kw"], ".4f"),
        _fmt(values["rmse_kw"], ".4f"),
        _fmt(values["skill"], ".3f"),
        _fmt(values["fit_s"], ".1f"),
        _fmt(paper[0], ".4f") if paper else "—",
        _fmt(paper[1], ".2f") if paper else "—",
    ]
    tds = "".join(f'<td class="paper">{c}</td>' if i >= 6 else f"<td>{c}</td>" for i, c in enumerate(cells))
    return f"<tr><td>{escape(name)}</td>{tds}</tr>"


def _weather_text(lag: int) -> str:
    if lag == 0:
        return "All models see the weather at the target time (a perfect weather forecast, as in the paper)."
    return f"Models see the weather only up to {lag} step(s) before the target time (no weather forecast)."


def _step_text(index: pd.DatetimeIndex) -> str:
    minutes = (index[1] - index[0]).total_seconds() / 60.0
    return f"{minutes / 60:g} h" if minutes >= 60 else f"{minutes:g} min"


def _fmt(value: object, spec: str) -> str:
    return "—" if not isinstance(value, (int, float)) or not math.isfinite(value) else format(value, spec)


def _day_plot(result: ComparisonResult) -> str:
    day = plot_day(result.forecasts)
    fig, ax = plt.subplots(figsize=(10, 4), dpi=100)
    ax.plot(day.index, day["actual"], color="black", linewidth=2.0, label="actual")
    for name in (c for c in day.columns if c != "actual"):
        ax.plot(day.index, day[name], linewidth=1.0, label=name)
    ax.set_ylabel("power (kW)")
    ax.set_xlabel(f"time ({day.index.tz})")
    ax.set_title(f"{result.dataset.upper()}: one-step-ahead forecasts, {day.index[0]:%Y-%m-%d %H:%M} to {day.index[-1]:%Y-%m-%d %H:%M}")
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    fig.autofmt_xdate()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")
