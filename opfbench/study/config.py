"""What a study runs: the grid {case} × {strategy} × {k} × {night mode} × {forecast} over a
period, checked before any work (unknown names, malformed night windows, empty grids) and
with duplicated grid values dropped (each drop is reported as a note).

Night modes: "connected" keeps PV inverters on the grid at night with whatever small
output the data show (Q limited by the usual capability, so ≈ 0); "disconnected" sets PV
active power to 0 during the night hours (no P, no Q); "connected-q" keeps them connected
at night with the S-limited "Q at night" capability |Q| ≤ √(S̄² − P²) (beyond the paper).
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass, field, replace

from opfbench.capability import PAPER_KS, check_reserve
from opfbench.errors import InputError
from opfbench.forecasting.names import MODEL_NAMES
from opfbench.formulations.acopf_options import ACOPF_SOLVERS, check_option
from opfbench.learned.fitted import Fitted
from opfbench.registry.catalog import configuration, specs
from opfbench.registry.references import DEFAULT_RUN
from opfbench.registry.specs import StrategySpec
from opfbench.study.price import DEFAULT_CURRENCY, DEFAULT_PRICE_PER_KWH, DEFAULT_PRICE_SOURCE

NIGHT_MODES = ("connected", "disconnected", "connected-q")
DEFAULT_NIGHT = "20:00-05:00"
CHUNKS = ("auto", "6h", "day", "week", "month")
FORECAST_SOURCES = ("off", "oracle")  # besides a forecasting model's name (`opfbench.forecasting.names`)
#: The optional long tables (`study.run_tables.detail_rows`), in the order they are written.
DETAIL_TABLES = ("der_q", "bus_v")
SHORT_PERIOD_H = 48.0  # periods up to two days: 6-hour chunks ("auto") and the per-DER Q table by default
_WINDOW = re.compile(r"^([01]\d|2[0-3]):([0-5]\d)-([01]\d|2[0-3]):([0-5]\d)$")
#: Config fields that do not change any result (they only label the report); a run folder
#: resumes across changes of these.
LABEL_FIELDS = ("price_per_kwh", "currency", "price_source")


def check_night(night: str) -> str:
    """`night` must be "sun" or a clock window "HH:MM-HH:MM" (24 h, not empty)."""
    m = _WINDOW.match(night)
    if night != "sun" and (m is None or m.group(1, 2) == m.group(3, 4)):
        raise InputError(f"night must be 'sun' or a non-empty clock window 'HH:MM-HH:MM' (e.g. 20:00-05:00), got {night!r}")
    return night


def unique_grid(fields: dict, labels: dict[str, str]) -> tuple[dict, tuple[str, ...]]:
    """`fields` with the grid values of each key of `labels` as a tuple without repeats
    (first kept; k values as floats, strategies compared by their canonical labels,
    `registry.configuration`), and notes naming what was dropped, by label."""
    out, notes = dict(fields), []
    for key, label in labels.items():
        if key not in fields:
            continue
        values: tuple = tuple(fields[key])
        if key == "ks":
            values = tuple(float(v) for v in values)
        elif key == "strategies":
            values = tuple(configuration(str(v)).label for v in values)
        out[key] = tuple(dict.fromkeys(values))
        if len(out[key]) < len(values):
            dropped = [v for i, v in enumerate(values) if v in values[:i]]
            notes.append(f"note: duplicated {label} dropped: {', '.join(str(v) for v in dropped)}")
    return out, tuple(notes)


def strategies_for(strategies: tuple[str, ...], forecast: str, chosen: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """The strategies (configuration labels) a forecast source runs: all with "off"; under a
    forecast only those the registry says read one (`uses_forecast`) — any other would
    repeat its "off" rows — and, where `chosen` is given, only those of it."""
    if forecast == "off":
        return strategies
    return tuple(s for s in strategies if (chosen is None or s in chosen) and _spec(s).uses_forecast)


def check_something_to_run(
    strategies: tuple[str, ...], forecasts: tuple[str, ...], chosen: tuple[str, ...] | None = None
) -> None:
    """InputError when no strategy runs under any of the forecasts (`strategies_for`)."""
    if not any(strategies_for(strategies, source, chosen) for source in forecasts):
        readers = [s.name for s in specs() if s.uses_forecast]
        raise InputError(
            f"nothing to run: only the strategies that read a forecast ({', '.join(readers)}) run under "
            f"forecast {', '.join(forecasts)}, and the grid has none of them"
        )


@dataclass(frozen=True)
class StudyConfig:
    """The grid and period of a run (see the module docstring; periods in
    `opfbench.study.periods`). `forecast` lists forecast sources for Algorithm 3: "off",
    "oracle" (P^F = the next step's actual output) or a forecasting model's name whose PV
    forecasts `opfbench forecast --dataset pv --out DIR` wrote to `forecast_dir`.
    A forecast other than "off" runs only the strategies that read one (the registry's
    `uses_forecast`: every local rule passes through Algorithm 3's limit); the others would
    repeat their "off" rows; `forecast_strategies`, where given, narrows that to some of
    the strategies (`opfbench run`'s default grid: the paper's Algorithm 3 rules).
    `chunk`: the length of one task's slice of the period (6h/day/week/month, local time;
    "auto": 6h for periods of up to two days, so the paper day's tasks spread over the
    workers, month otherwise), fixed by the config and never by the number of workers. `detail`: also write the long
    tables of per-DER Q and per-bus V (None: per-DER Q alone for periods of ≤ 2 days, which
    the report plots; a tuple: those of `DETAIL_TABLES`); `detail_tables` the names resolved from it (`with_period`). Price fields only label the report.
    `frontier` False: the run solves no optimum for the frontier (the rules alone, e.g. on a
    feeder too large for the three-phase OPF in the time at hand): its summary has the
    loss-only columns and no figure at equal compliance; at its default (True) the config
    is the one without it (manifest and digest).
    `acopf_solver`: "auto" (the SOCP certifies the AC optimum where it can, IPOPT solves the
    rest) or "ipopt" (IPOPT on every step: the solver's own outcomes, as the paper asks) —
    the run-level setting of every option that declares it (`registry.Option.setting`).
    `strategies` are configuration labels (`NAME:key=value,…`), kept canonical
    (`registry.configuration`); `plugins` and `plugin_digests` (derived, not given) name
    the plugins those strategies come from (a file's absolute path) and their fingerprints
    (`plugins.PluginSource.digest`: the source and what it was seen to depend on), so a
    changed plugin or helper is another configuration; `notes` say what each plugin's
    fingerprint cannot see. `fitted` (derived by the run, not given): the learned
    configurations' fitted rules per case (`study.training`), their hashes part of the
    configuration."""

    cases: tuple[str, ...] = ("paper33",)
    strategies: tuple[str, ...] = DEFAULT_RUN
    ks: tuple[float, ...] = PAPER_KS
    night_modes: tuple[str, ...] = NIGHT_MODES
    night: str = DEFAULT_NIGHT
    forecast: tuple[str, ...] = ("off", "oracle")
    period: str = "paper-day"
    step_minutes: float | None = None
    chunk: str = "auto"
    detail: bool | None | tuple[str, ...] = None
    detail_tables: tuple[str, ...] = ()
    acopf_solver: str = "auto"
    frontier: bool = True
    forecast_dir: str = "reports/forecast"
    price_per_kwh: float = DEFAULT_PRICE_PER_KWH
    currency: str = DEFAULT_CURRENCY
    price_source: str = DEFAULT_PRICE_SOURCE
    forecast_strategies: tuple[str, ...] | None = None
    plugins: tuple[str, ...] = ()
    plugin_digests: tuple[str, ...] = ()
    fitted: tuple[Fitted, ...] = ()
    notes: tuple[str, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        from opfbench.plugins import load

        labels = tuple(configuration(label).label for label in self.strategies)
        object.__setattr__(self, "strategies", labels)
        if self.forecast_strategies is not None:
            chosen = tuple(dict.fromkeys(configuration(label).label for label in self.forecast_strategies))
            stray = [label for label in chosen if label not in labels]
            if stray:
                raise InputError(f"forecast strategies {', '.join(stray)} are not among the run's strategies")
            object.__setattr__(self, "forecast_strategies", chosen)
        sources = tuple(dict.fromkeys(s.source for s in map(_spec, labels) if s.source != "opfbench"))
        loaded = [load(ref) for ref in sources]
        object.__setattr__(self, "plugins", tuple(p.ref for p in loaded))
        object.__setattr__(self, "plugin_digests", tuple(p.digest for p in loaded))
        said = tuple(p.note() for p in loaded)
        object.__setattr__(self, "notes", self.notes + tuple(n for n in said if n not in self.notes))
        for mode in self.night_modes:
            if mode not in NIGHT_MODES:
                raise InputError(f"unknown night mode {mode!r}; choose from {', '.join(NIGHT_MODES)}")
        for k in self.ks:
            check_reserve(k)
        for source in self.forecast:
            if source not in FORECAST_SOURCES + MODEL_NAMES:
                raise InputError(
                    f"unknown forecast source {source!r}; choose {', '.join(FORECAST_SOURCES)} or a forecasting model's "
                    f"name ({', '.join(MODEL_NAMES)}), whose forecasts are read from the forecast folder "
                    f"({self.forecast_dir})"
                )
        if not (isinstance(self.currency, str) and self.currency.strip() and self.currency.isprintable()):
            raise InputError(f"currency must be a printable, non-empty label (e.g. EUR), got {self.currency!r}")
        if isinstance(self.detail, tuple) and not set(self.detail) <= set(DETAIL_TABLES):
            raise InputError(f"unknown detail table(s) {', '.join(sorted(set(self.detail) - set(DETAIL_TABLES)))}")
        if self.chunk not in CHUNKS:
            raise InputError(f"unknown chunk {self.chunk!r}; choose from {', '.join(CHUNKS)}")
        check_night(self.night)
        check_option("AC OPF solver", self.acopf_solver, ACOPF_SOLVERS)
        if not (self.cases and self.strategies and self.ks and self.night_modes and self.forecast):
            raise InputError("nothing to run: give at least one case, strategy, k, night mode and forecast")
        check_something_to_run(self.strategies, self.forecast, self.forecast_strategies)

    @classmethod
    def build(cls, **fields) -> "StudyConfig":
        """A config with duplicated grid values dropped (strategies compared by their canonical
        labels); `notes` say what was dropped."""
        labels = {"cases": "cases", "strategies": "strategies", "ks": "k values", "night_modes": "night modes"}
        unique, notes = unique_grid(fields, labels | {"forecast": "forecast sources"})
        return cls(**unique, notes=notes)

    def strategies_for(self, forecast: str) -> tuple[str, ...]:
        """The strategies a forecast source runs (`strategies_for`, narrowed to
        `forecast_strategies` where given)."""
        return strategies_for(self.strategies, forecast, self.forecast_strategies)

    def settings(self) -> dict[str, str]:
        """The run-level settings options may take their defaults from (`Option.setting`)."""
        return {"acopf_solver": self.acopf_solver}

    def as_dict(self) -> dict:
        """The manifest's `config` (JSON-ready)."""
        out = asdict(self)
        out.pop("notes")
        out["fitted"] = [f.as_dict() for f in self.fitted]
        if out["frontier"]:
            out.pop("frontier")  # the default: the config as it was before the option
        return {key: list(v) if isinstance(v, tuple) else v for key, v in out.items()}

    def digest(self) -> str:
        """Hash of everything that changes results (not the price labels, nor the fitted
        rules: they follow from the rest, and each task's definition holds its case's; nor
        where the plugins lie: their fingerprints say what they are)."""
        body = {k: v for k, v in self.as_dict().items() if k not in (*LABEL_FIELDS, "fitted", "plugins")}
        return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]

    def with_period(self, step_minutes: float, hours: float) -> "StudyConfig":
        """The config with what the period decides filled in: its step, the long tables
        (`detail`) and the chunk ("auto"), for a period of `hours`."""
        short = hours <= SHORT_PERIOD_H
        if isinstance(self.detail, tuple):
            tables = tuple(t for t in DETAIL_TABLES if t in self.detail)
        else:
            tables = DETAIL_TABLES if self.detail else ("der_q",) if self.detail is None and short else ()
        chunk = ("6h" if short else "month") if self.chunk == "auto" else self.chunk
        return replace(self, step_minutes=step_minutes, detail_tables=tables, chunk=chunk)


def _spec(label: str) -> StrategySpec:
    return configuration(label).spec
