"""How a local rule joins the registry: the `local_rule` decorator, used by the built-in
rules (`paper`, `standards`, `learned`) and by plugins alike, and the engine's options
every rule takes.

A rule is a function `target(m, **options) -> (S, n_der)` MVAr of the DER's measurements
(`rules.Measurements`, only what it `reads`) — or, a rule that `curtails` (Volt-Watt),
`rules.Targets`: Q targets and a cap on active power; the decorator registers a strategy
whose runner is the local-rule engine (`rule_engine.run_rule`), which clips the targets to
the limits and settles a rule that reads |V| or line flows. A rule that reads a forecast
takes `safe` (Algorithm 3's cap) and the inverter's `priority` (which power yields where
the capability binds), a closed-loop one the engine's settling options. A rule declared
outside opfbench (a plugin) is checked on made-up measurements when it registers (`probe`).
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from opfbench.errors import InputError
from opfbench.registry.options import Option, OptionValue
from opfbench.registry.specs import OPFBENCH, StrategySpec, register, source_of
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario
from opfbench.strategies.rule_engine import run_rule
from opfbench.strategies.rules import (
    DEFAULT_SETTLING,
    FEEDBACK,
    PRIORITIES,
    READS,
    RESIDUAL,
    Measurements,
    Rule,
    Target,
    targets,
)


def _positive(value: OptionValue) -> str | None:
    return None if isinstance(value, (int, float)) and value > 0 else f"must be > 0, got {value}"


def _step(value: OptionValue) -> str | None:
    return None if isinstance(value, float) and 0 < value <= 1 else f"a step factor lies in (0, 1], got {value}"


MAX_STEPS = 1000
"""The closed loop's largest `max_steps` (10× the default): it sizes the work of every
snapshot that does not settle; one the damped iteration has not settled by then is
recorded not-settled."""


def _steps(value: OptionValue) -> str | None:
    ok = isinstance(value, int) and 0 <= value <= MAX_STEPS
    return None if ok else f"lies in 0..{MAX_STEPS} (each step is a power flow of every snapshot not yet settled), got {value}"


SAFE = Option("safe", False, "Algorithm 3: cap the forecast-aware limit at the physical capability at P^C")
PRIORITY = Option(
    "priority",
    "p",
    "which power yields where the capability binds: p (active priority: Q within what P leaves) or "
    "q (reactive priority: P curtailed so that (1 − k)·Qmax(P) covers Q)",
    choices=PRIORITIES,
)
#: The closed-loop engine's options (`rules.Settling`), on every rule that reads |V| or flows.
SETTLING_OPTIONS = (
    Option("max_steps", DEFAULT_SETTLING.max_steps, "damped steps before a snapshot counts as not-settled", check=_steps),
    Option(
        "tol_v_pu",
        DEFAULT_SETTLING.tol_v_pu,
        "settled: largest bus-voltage change of the last step ≤ this, p.u.",
        check=_positive,
    ),
    Option(
        "tol_q_mvar",
        DEFAULT_SETTLING.tol_q_mvar,
        "settled: largest change the rule still asks of Q (MVAr) or, where it curtails, of P (MW) ≤ this",
        check=_positive,
    ),
    Option(
        "step_factor",
        DEFAULT_SETTLING.step_factor,
        "damping α of Q += α·(target − Q), the first step's when adaptive",
        check=_step,
    ),
    Option("adaptive", DEFAULT_SETTLING.adaptive, "adapt α per DER from successive voltage changes (OpenDSS InvControl)"),
)
ENGINE_OPTIONS = frozenset(o.name for o in (SAFE, PRIORITY, *SETTLING_OPTIONS))
CLOSED_LOOP_COLUMNS = {RESIDUAL: "largest |clip(target) − Q| at the last iterate, MVAr (≤ tol_q_mvar when settled)"}


def engine_runner(name: str, target: Target, reads: frozenset[str], curtails: bool = False) -> Callable[..., StrategyResult]:
    """The runner of the rule `target`: the engine's options (safe, priority, settling) to
    the engine, the others to the target."""
    rule = Rule(name, target, reads, curtails)

    def run(scenario: Scenario, k: float, **options: Any) -> StrategyResult:
        engine = {key: v for key, v in options.items() if key in ENGINE_OPTIONS}
        settling = dataclasses.replace(
            DEFAULT_SETTLING, **{key: v for key, v in engine.items() if key not in ("safe", "priority")}
        )
        rule_options = {key: v for key, v in options.items() if key not in ENGINE_OPTIONS}
        safe, priority = bool(engine.get("safe", False)), str(engine.get("priority", "p"))
        return run_rule(name, rule, scenario, k, rule_options, safe=safe, settling=settling, priority=priority)

    return run


T = TypeVar("T", bound=Target)


def local_rule(
    name: str,
    *,
    reads: Sequence[str],
    options: Mapping[str, OptionValue | Option] | Sequence[Option] | None = None,
    summary: str = "",
    columns: Mapping[str, str] | None = None,
    uses_forecast: bool = True,
    check: Callable[[dict], None] | None = None,
    fit: Callable[..., Any] | None = None,
    snapshot_wise: bool = False,
    curtails: bool = False,
) -> Callable[[T], T]:
    """Register the decorated `target(m, **options) -> (S, n_der)` MVAr as the local rule
    `name` (see the module docstring). `options`: Options, or name → default (bool, int,
    float, str or a tuple of floats; the default's type is the option's). `uses_forecast`:
    the rule's limit is Algorithm 3's where the scenario has a forecast (it then takes
    `safe`). `check(options)` refuses option combinations; `fit(name, training, options)`
    makes it a learned rule whose declared options are the fit's. `curtails`: the function
    returns `rules.Targets` (Q targets and a cap on active power, MW) — a rule that may
    deliver less active power than it has. `snapshot_wise`: the target of a snapshot reads
    only that snapshot's measurements (the engine treats snapshots independently, so the
    study may run the rule once on the distinct snapshots of several night modes;
    `StrategySpec.snapshot_wise`). InputError for a bad name, reads, option or signature,
    or (a plugin) targets of the wrong shape or not finite on a probe."""

    def decorate(target: T) -> T:
        source = source_of(target.__module__)
        unknown = set(reads) - set(READS)
        if unknown:
            raise InputError(
                f"rule {name!r}: unknown measurement(s) {', '.join(sorted(unknown))}; it may read {', '.join(READS)}"
            )
        items = options.items() if isinstance(options, Mapping) else ((o.name, o) for o in options or ())
        declared = tuple(_option(key, value, name) for key, value in items)
        closed = bool(FEEDBACK & set(reads))
        engine = ((SAFE, PRIORITY) if uses_forecast else ()) + (SETTLING_OPTIONS if closed else ())
        spec = StrategySpec(
            name,
            "local",
            summary or (inspect.getdoc(target) or f"local rule {name}").splitlines()[0],
            engine_runner(name, target, frozenset(reads), curtails),
            target=target,
            reads=tuple(reads),
            closed_loop=closed,
            options=(*declared, *engine),
            uses_forecast=uses_forecast,
            check=check,
            columns=dict(CLOSED_LOOP_COLUMNS if closed else {}) | dict(columns or {}),
            fit=fit,
            fit_options=tuple(o.name for o in declared) if fit is not None else (),
            snapshot_wise=snapshot_wise,
            source=source,
            module=target.__module__,
            curtails=curtails,
        )
        _check_signature(spec, target, declared)
        if source != OPFBENCH:
            probe(spec, target)
        register(spec)
        return target

    return decorate


def _option(key: str, value: OptionValue | Option, rule: str) -> Option:
    if not key.isidentifier():
        raise InputError(f"rule {rule!r}: option name {key!r} must be a Python identifier")
    if key in ENGINE_OPTIONS:
        raise InputError(f"rule {rule!r}: option name {key!r} is the engine's ({', '.join(sorted(ENGINE_OPTIONS))})")
    if isinstance(value, Option):
        option = value
    elif not isinstance(value, (bool, int, float, str, tuple)):
        raise InputError(f"rule {rule!r}: option {key} has default {value!r}; use a bool, int, float, str or tuple of floats")
    else:
        option = Option(key, tuple(float(v) for v in value) if isinstance(value, tuple) else value, f"option of {rule}")
    try:
        option.validate(option.default)
    except InputError as exc:
        raise InputError(f"rule {rule!r}: option {option.name}'s default {option.format(option.default)}: {exc}") from None
    return option


def _check_signature(spec: StrategySpec, target: Callable, declared: tuple[Option, ...]) -> None:
    """The target takes the measurements first, and every declared option by keyword."""
    try:
        params = list(inspect.signature(target).parameters.values())
    except (TypeError, ValueError):
        raise InputError(f"rule {spec.name!r}: {target!r} is not a function with a signature") from None
    positional = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    if not params or params[0].kind not in positional:
        raise InputError(
            f"rule {spec.name!r}: the function must take the measurements as its first argument, e.g. def {spec.name.replace('-', '_')}(m, ...)"
        )
    rest = params[1:]
    by_kw = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in rest)
    names = {p.name for p in rest if p.kind is not inspect.Parameter.VAR_POSITIONAL}
    missing = [o.name for o in declared if o.name not in names and not by_kw]
    if missing:
        raise InputError(f"rule {spec.name!r}: the function takes no argument {', '.join(missing)} for its declared option(s)")
    extra = [
        p.name
        for p in rest
        if p.default is inspect.Parameter.empty
        and p.name not in {o.name for o in declared}
        and p.kind not in (inspect.Parameter.VAR_KEYWORD, inspect.Parameter.VAR_POSITIONAL)
    ]
    if extra:
        raise InputError(f"rule {spec.name!r}: the function's argument(s) {', '.join(extra)} are neither options nor defaulted")


def probe(spec: StrategySpec, target: Target) -> None:
    """Call a rule on made-up measurements (3 snapshots, 2 DER: |V| 0.9–1.1 p.u., P at
    0–100 % of rating, loads and line flows of both signs) with its default options:
    InputError unless it returns finite targets shaped (3, 2)."""
    n_rows, rating = 3, np.array([0.6, 0.5])
    values = {
        "v_pu": np.array([[0.95, 1.0], [1.02, 1.05], [0.9, 1.1]]),
        "p_mw": np.array([[0.0, 0.25], [0.3, 0.5], [0.6, 0.1]]),
        "p_forecast_mw": np.array([[0.1, 0.2], [0.3, 0.5], [0.5, 0.2]]),
        "load_p_mw": np.array([[0.1, 0.06], [0.2, 0.0], [0.05, 0.1]]),
        "load_q_mvar": np.array([[0.06, -0.02], [0.1, 0.0], [0.03, 0.05]]),
        "line_mva": np.array([[[-0.2 - 0.1j, 0.1 + 0.05j]] * 2] * n_rows),
    }
    for arr in values.values():
        arr.setflags(write=False)  # as the engine's: a rule never writes into its measurements
    m = Measurements(frozenset(spec.reads), values, n_rows, rating, rating, np.array(["PV", "DFIG"]), np.ones((2, 2), dtype=bool))
    rule = Rule(spec.name, target, frozenset(spec.reads), spec.curtails)
    options = {o.name: o.default for o in spec.options if o.name not in ENGINE_OPTIONS}
    out = targets(rule, m, options, n_rows)
    if not out.finite.all():
        raise InputError(
            f"rule {spec.name!r} returned NaN or inf on a probe (|V| 0.9–1.1 p.u., P 0–100 % of rating, default "
            "options); a rule must give a finite Q target for every DER"
        )
