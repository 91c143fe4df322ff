"""The one page frame and stylesheet of every HTML page opfbench writes (the benchmark
report, the forecast pages): Jinja2 templates shipped in `opfbench/report/templates`,
autoescape on, tables from pandas (escaped), Plotly's JavaScript inlined once per page."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import jinja2
import numpy as np
import pandas as pd

from opfbench import __version__
from opfbench.report.plots import Plot, plot_template


@dataclass
class Block:
    """One piece of a section: kind ∈ heading, note, missing, error, meta, table, plot, claims."""

    kind: str
    text: str = ""
    html: str = ""
    rows: int = 0
    collapsed: bool = False
    command: str = ""
    items: list[tuple[str, str]] = field(default_factory=list)
    plot: Plot | None = None
    claims: list = field(default_factory=list)


@dataclass
class Section:
    id: str
    title: str
    intro: str = ""
    blocks: list[Block] = field(default_factory=list)

    def add(self, *blocks: Block) -> Section:
        self.blocks.extend(blocks)
        return self


@lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("opfbench.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )


@lru_cache(maxsize=1)
def plotly_js() -> str:
    """plotly.js (minified bundle), to inline once per page."""
    from plotly.offline import get_plotlyjs

    return get_plotlyjs()


def render(template: str, title: str, subtitle: str = "", plots: bool = False, **context: object) -> str:
    """Render `template` (extends page.html.j2) into a complete, self-contained page."""
    return (
        environment()
        .get_template(template)
        .render(
            title=title,
            subtitle=subtitle,
            version=__version__,
            plotly_js=plotly_js() if plots else "",
            plot_template=plot_template() if plots else "",
            **context,
        )
    )


def _digits(column: str) -> int:
    name = column.lower()
    if "mse" in name:
        return 5
    if name.endswith(("pu", "p.u.")) or "share" in name or "mvar" in name or name == "skill":
        return 4 if "share" not in name else 3
    return 2


def _cell(value: object, digits: int) -> str:
    if isinstance(value, (float, np.floating)):
        return "—" if not math.isfinite(value) else f"{value:,.{digits}f}"
    return "—" if value is None or value is pd.NA else str(value)


UNITS = {
    "kwh": "kWh",
    "kw": "kW",
    "mw": "MW",
    "mvar": "MVAr",
    "pct": "%",
    "pu": "p.u.",
    "ms": "ms",
    "s": "s",
    "min": "min",
    "mb": "MB",
}
"""A column name's last word → the unit its heading shows in parentheses."""
WORDS = {
    "opf": "OPF",
    "acopf": "AC OPF",
    "socp": "SOCP",
    "avg": "mean",
    "pv": "PV",
    "der": "DER",
    "eq": "at equal compliance",
    "eps": "band widened by ε",
}
PHRASES = {"loss only": "loss-only"}
"""Word pairs a heading writes as one."""


def heading(column: str) -> str:
    """A table column's heading for a reader: `energy_kwh` → "energy (kWh)",
    `opf_share_pct` → "OPF share (%)"; names without underscores stay as they are."""
    if "_" not in column:
        return column
    *words, last = column.split("_")
    if last not in UNITS:
        text = " ".join(WORDS.get(w, w) for w in [*words, last])
    else:
        text = " ".join(WORDS.get(w, w) for w in words) + f" ({UNITS[last]})"
    for pair, joined in PHRASES.items():
        text = text.replace(pair, joined)
    return text


def table_html(frame: pd.DataFrame) -> str:
    """`frame` as an HTML table (template table.html.j2, every cell escaped): headings for
    a reader (`heading`, the data's column name as the heading's title), numbers
    right-aligned and formatted per column (p.u. 4 decimals, MSE 5, else 2), NaN as "—"."""
    numeric = [pd.api.types.is_numeric_dtype(frame[c]) and not pd.api.types.is_bool_dtype(frame[c]) for c in frame.columns]
    digits = [_digits(str(c)) for c in frame.columns]
    rows = [[_cell(v, d) for v, d in zip(row, digits, strict=True)] for row in frame.itertuples(index=False, name=None)]
    return (
        environment()
        .get_template("table.html.j2")
        .render(columns=[(str(c), heading(str(c)), n) for c, n in zip(frame.columns, numeric, strict=True)], rows=rows)
    )


def table(frame: pd.DataFrame, text: str = "", collapse_over: int = 40) -> Block:
    """A table block, folded into <details> when it has more than `collapse_over` rows."""
    return Block("table", text=text, html=table_html(frame), rows=len(frame), collapsed=len(frame) > collapse_over)
