"""Your own local rule in one file, with no edit to opfbench.

A plugin is a Python module (a file `my_rule.py`, or an installed module) that decorates
a function of the DER's local measurements:

    import numpy as np
    from opfbench.plugins import local_rule

    @local_rule("my-rule", reads=("v", "load"), options={"share": 0.5})
    def my_rule(m, share):
        # Q target in MVAr (positive = injected): a share of the own-bus reactive load,
        # doubled below 0.95 p.u.
        return share * m.load_q_mvar * np.where(m.v_pu < 0.95, 2.0, 1.0)

The function receives `strategies.engine.Measurements` (only what `reads` declares) and
the options as keywords, and returns each DER's Q target (S, n_der) in MVAr. The engine
clips it to the usual limits (reserve k, capability, Algorithm 3, "Q at night"), and
solves a rule that reads |V| or line flows for its closed-loop steady state. It is then a
strategy like the built-in ones: labels with options (`my-rule:share=0.8`), every table, the
report, `snapshot`, `run` and `fault`.

Loading: `--plugin FILE.py|MODULE` (repeatable) on the commands, or the entry-point group
`opfbench.strategies` of an installed package (loaded when a name is not known, or when
every strategy is listed). A plugin is checked when it loads, before any work: it must
import, register at least one strategy, have a signature that takes every declared
option, and return finite targets of the right shape on a probe; otherwise one
InputError names it. `opfbench run` records each plugin's reference and source digest in
the run's config (a changed plugin is another configuration) and ships the source of a
file plugin to the worker processes, which load it before running (`ensure`); a module
plugin must be importable on the workers.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import re
import sys
import types
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np

from opfbench.errors import InputError
from opfbench.registry import (
    CLOSED_LOOP_COLUMNS,
    PRIORITY,
    SAFE,
    SETTLING_OPTIONS,
    STRATEGIES,
    Option,
    OptionValue,
    StrategySpec,
    register,
)

__all__ = ["Option", "PluginSource", "ensure", "load", "load_entry_points", "loaded", "local_rule", "probe", "unload"]
from opfbench.strategies.rules import FEEDBACK, Measurements, Rule, targets

ENTRY_POINT_GROUP = "opfbench.strategies"
_RESERVED = {o.name for o in (SAFE, PRIORITY, *SETTLING_OPTIONS)}


@dataclass(frozen=True)
class PluginSource:
    """A loaded plugin: `ref` as given (a .py path or a module name), the module it was
    loaded as, the sha256 of its source, the source text of a file plugin (shipped to
    workers; None for an installed module) and the strategies it registered."""

    ref: str
    module: str
    digest: str
    text: str | None
    strategies: tuple[str, ...]


_loaded: dict[str, PluginSource] = {}
_loading: list[str] = []
_entry_points_loaded = False


@contextmanager
def _as_source(ref: str) -> Iterator[None]:
    _loading.append(ref)
    try:
        yield
    finally:
        _loading.pop()


def local_rule(
    name: str,
    *,
    reads: Sequence[str],
    options: Mapping[str, OptionValue | Option] | None = None,
    summary: str = "",
    columns: Mapping[str, str] | None = None,
    curtails: bool = False,
) -> Callable[[Callable], Callable]:
    """Register the decorated function `target(m, **options) -> (S, n_der)` MVAr as the
    local rule `name` (see the module docstring). `options`: name → default (bool, int,
    float, str or a tuple of floats; the default's type is the option's) or an `Option`.
    The rule reads a forecast (its limit is Algorithm 3's), so it takes `safe`, and the
    inverter's `priority`; a rule of |V| or flows also takes the engine's settling options.
    `curtails`: the function returns `opfbench.strategies.rules.Targets` (Q targets and a
    cap on active power, MW) instead of Q targets alone. InputError for a bad name, reads,
    option or signature, or targets of the wrong shape or not finite on a probe."""

    def decorate(target: Callable) -> Callable:
        source = _loading[-1] if _loading else getattr(target, "__module__", "plugin")
        declared = tuple(_option(key, value, name) for key, value in (options or {}).items())
        closed = bool(FEEDBACK & set(reads))
        spec = StrategySpec(
            name,
            "local",
            summary or (inspect.getdoc(target) or f"local rule {name}").splitlines()[0],
            rule=target,
            reads=tuple(reads),
            options=(*declared, SAFE, PRIORITY, *(SETTLING_OPTIONS if closed else ())),
            uses_forecast=True,
            columns=dict(CLOSED_LOOP_COLUMNS if closed else {}) | dict(columns or {}),
            source=source,
            curtails=curtails,
        )
        _check_signature(spec, target, declared)
        probe(spec)
        register(spec)
        return target

    return decorate


def _option(key: str, value: OptionValue | Option, rule: str) -> Option:
    if not key.isidentifier():
        raise InputError(f"rule {rule!r}: option name {key!r} must be a Python identifier")
    if key in _RESERVED:
        raise InputError(f"rule {rule!r}: option name {key!r} is the engine's ({', '.join(sorted(_RESERVED))})")
    if isinstance(value, Option):
        return value
    if not isinstance(value, (bool, int, float, str, tuple)):
        raise InputError(f"rule {rule!r}: option {key} has default {value!r}; use a bool, int, float, str or tuple of floats")
    return Option(key, tuple(float(v) for v in value) if isinstance(value, tuple) else value, f"option of {rule}")


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


def probe(spec: StrategySpec) -> None:
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
    m = Measurements(frozenset(spec.reads), values, n_rows, rating, rating, np.array(["PV", "DFIG"]), np.ones((2, 2), dtype=bool))
    rule = Rule(spec.name, spec.rule, frozenset(spec.reads), spec.curtails)  # type: ignore[arg-type]
    options = {o.name: o.default for o in spec.options if o.name not in _RESERVED}
    out = targets(rule, m, options, n_rows)
    if not out.finite.all():
        raise InputError(
            f"rule {spec.name!r} returned NaN or inf on a probe (|V| 0.9–1.1 p.u., P 0–100 % of rating, default "
            "options); a rule must give a finite Q target for every DER"
        )


def _digest(text: str | bytes) -> str:
    return hashlib.sha256(text.encode() if isinstance(text, str) else text).hexdigest()


def _is_path(ref: str) -> bool:
    return ref.endswith(".py") or "/" in ref or "\\" in ref


def _exec_text(ref: str, text: str, filename: str) -> str:
    """Run a plugin file's text as a fresh module; its name carries the digest."""
    stem = re.sub(r"\W", "_", Path(filename).stem)
    module_name = f"opfbench_plugin_{stem}_{_digest(text)[:12]}"
    if module_name in sys.modules:
        return module_name
    module = types.ModuleType(module_name)
    module.__file__ = filename
    sys.modules[module_name] = module
    try:
        with _as_source(ref):
            exec(compile(text, filename, "exec"), module.__dict__)
    except BaseException:
        sys.modules.pop(module_name, None)
        raise
    return module_name


def load(ref: str) -> PluginSource:
    """Load the plugin `ref` (a .py file path, or an importable module name) and check it;
    InputError naming it if it cannot be loaded or registers no (valid) strategy."""
    if ref in _loaded:
        return _loaded[ref]
    try:
        if _is_path(ref):
            path = Path(ref)
            if not path.is_file():
                raise InputError(f"plugin {ref}: no such file")
            try:
                text = path.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise InputError(f"plugin {ref}: cannot read it ({exc})") from None
            module, digest = _exec_text(ref, text, str(path.resolve())), _digest(text)
        else:
            with _as_source(ref):
                imported = importlib.import_module(ref)
            module, text, digest = ref, None, _file_digest(imported)
    except Exception as exc:  # nothing of a plugin that fails half-way stays registered
        for name in [n for n, s in STRATEGIES.items() if s.source == ref]:
            del STRATEGIES[name]
        if isinstance(exc, InputError):
            message = str(exc)
            raise InputError(message if message.startswith(f"plugin {ref}") else f"plugin {ref}: {message}") from None
        raise InputError(f"plugin {ref}: cannot import it ({type(exc).__name__}: {exc})") from None
    names = tuple(n for n, s in STRATEGIES.items() if s.source == ref)
    if not names:
        raise InputError(f"plugin {ref} registers no strategy: decorate a function with @opfbench.plugins.local_rule(...)")
    _loaded[ref] = PluginSource(ref, module, digest, text if _is_path(ref) else None, names)
    return _loaded[ref]


def _file_digest(module: types.ModuleType) -> str:
    file = getattr(module, "__file__", None)
    return _digest(Path(file).read_bytes()) if file and Path(file).is_file() else ""


def ensure(sources: Sequence[PluginSource]) -> None:
    """Load plugins in a worker process as the run's main process loaded them: a file
    plugin from its shipped text, a module by name; InputError if a module's source is
    not the one the run recorded."""
    for src in sources:
        if src.ref in _loaded:
            continue
        if src.text is not None:
            _exec_text(src.ref, src.text, src.ref)
            _loaded[src.ref] = src
            continue
        got = load(src.ref)
        if src.digest and got.digest != src.digest:
            raise InputError(
                f"plugin {src.ref}: its source on this worker differs from the run's (digest {got.digest[:12]} ≠ {src.digest[:12]})"
            )


def unload(ref: str) -> None:
    """Forget the plugin `ref`: its strategies leave the registry (a notebook reloading an
    edited plugin, or a test cleaning up)."""
    for name in [n for n, s in STRATEGIES.items() if s.source == ref]:
        del STRATEGIES[name]
    source = _loaded.pop(ref, None)
    if source is not None and source.text is not None:  # a file plugin's module: loaded anew next time
        sys.modules.pop(source.module, None)


def loaded(refs: Sequence[str] | None = None) -> tuple[PluginSource, ...]:
    """The loaded plugins (those of `refs` where given), in load order."""
    return tuple(src for ref, src in _loaded.items() if refs is None or ref in refs)


def source_of(strategy_source: str) -> PluginSource | None:
    """The loaded plugin a registered strategy came from (None for opfbench's own)."""
    return _loaded.get(strategy_source)


def load_entry_points() -> None:
    """Load every plugin of the `opfbench.strategies` entry-point group, once per process."""
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            load(ep.module)
        except InputError as exc:
            raise InputError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINT_GROUP}): {exc}") from None
