"""The page of a forecast run (`opfbench forecast --out DIR` writes it beside the forecasts):
metrics beside paper Table I, one test day plot, on the page frame and stylesheet of every
opfbench page (`opfbench.report.page`).

`forecast_section(result)` returns an HTML fragment; `forecast_page(result)` a
self-contained page (inline CSS, the plot as a base64 PNG; no script, no external resources).
"""

from __future__ import annotations

import base64
import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from opfbench.forecasting.experiment import ComparisonResult  # noqa: E402
from opfbench.report.page import environment, render, table  # noqa: E402
from opfbench.report.paper_figures import FORECAST_TABLE as PAPER_TABLE  # noqa: E402

__all__ = ["PAPER_TABLE", "forecast_page", "forecast_section", "html_page", "plot_day"]


def forecast_section(result: ComparisonResult) -> str:
    """HTML fragment: run description, metrics table with paper values, test-day plot."""
    s = result.settings
    f = result.forecasts
    description = (
        f"Training {result.train_range[0]} – {result.train_range[1]}; test {f.index[0]} – {f.index[-1]} ({len(f)} steps "
        f"of {_step_text(f.index)}). Rating {result.rating_kw:g} kW. Input window {s.window} steps; networks trained "
        f"{s.epochs} epochs of {s.windows_per_epoch or 'all'} windows (batch {s.batch_size}, Adam {s.learning_rate:g}, best "
        f"epoch on the last {s.train_config(result.seed).val_fraction:.0%} of the training windows); ARIMA order by AIC on "
        f"the last {s.arima_fit_samples} training steps; wavelet {s.wavelet}, {s.wavelet_level} levels, applied per input "
        f"window. Seed {result.seed}."
    )
    note = (
        f"MSE on the series min-max scaled with the training range of the power; MAPE over test samples whose actual "
        f"power exceeds {s.mape_threshold:.0%} of the rating; skill = 1 − RMSE/RMSE(persistence). "
        f"{_weather_text(result.weather_lag)} Paper values: SYSLAB (DTU) 2019 data at 5-min resolution, with a softmax "
        "output layer; our data and resolution differ, so only the ranking is comparable."
    )
    return (
        environment()
        .get_template("forecast_section.html.j2")
        .render(dataset=result.dataset, description=description, note=note, table=_metrics_table(result), png=_day_plot(result))
    )


def forecast_page(result: ComparisonResult) -> str:
    """Self-contained HTML page with `forecast_section(result)`."""
    return html_page(f"opfbench forecast — {result.dataset}", forecast_section(result))


def html_page(title: str, body: str) -> str:
    """The opfbench page frame around the HTML fragment `body` (trusted: built from templates)."""
    return render("forecast.html.j2", title, section=body)


def plot_day(forecasts: pd.DataFrame) -> pd.DataFrame:
    """The test day shown: 24 h from the first midnight (index time zone) of the test part
    when a full day follows it, else the first 24 h of the test part."""
    index = forecasts.index
    midnight = index[0].ceil("D")
    start = midnight if midnight + pd.Timedelta(days=1) <= index[-1] + (index[1] - index[0]) else index[0]
    return forecasts[(index >= start) & (index < start + pd.Timedelta(days=1))]


def _metrics_table(result: ComparisonResult) -> str:
    rows = []
    for name, run in result.runs.items():
        v = run.as_dict()
        paper = PAPER_TABLE.get(result.dataset, {}).get(name, (float("nan"), float("nan")))
        rows.append(
            {
                "model": name,
                "MSE (scaled)": v["mse_scaled"],
                "MAPE %": v["mape_pct"],
                "MAE kW": v["mae_kw"],
                "RMSE kW": v["rmse_kw"],
                "skill vs persistence": v["skill"],
                "fit s": v["fit_s"],
                "paper MSE": paper[0],
                "paper MAPE %": paper[1],
            }
        )
    return table(pd.DataFrame(rows)).html


def _weather_text(lag: int) -> str:
    if lag == 0:
        return "All models see the weather at the target time (a perfect weather forecast, as in the paper)."
    return f"Models see the weather only up to {lag} step(s) before the target time (no weather forecast)."


def _step_text(index: pd.DatetimeIndex) -> str:
    minutes = (index[1] - index[0]).total_seconds() / 60.0
    return f"{minutes / 60:g} h" if minutes >= 60 else f"{minutes:g} min"


def _day_plot(result: ComparisonResult) -> str:
    """The test day as a base64 PNG (matplotlib): the forecast page stays script-free."""
    day = plot_day(result.forecasts)
    fig, ax = plt.subplots(figsize=(10, 4), dpi=100)
    ax.plot(day.index, day["actual"], color="black", linewidth=2.0, label="actual")
    for name in (c for c in day.columns if c != "actual"):
        ax.plot(day.index, day[name], linewidth=1.0, label=name)
    ax.set_ylabel("power (kW)")
    ax.set_xlabel(f"time ({day.index.tz})")
    ax.set_title(
        f"{result.dataset.upper()}: one-step-ahead forecasts, {day.index[0]:%Y-%m-%d %H:%M} to {day.index[-1]:%Y-%m-%d %H:%M}"
    )
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    fig.autofmt_xdate()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")
