"""Your own local rule or formulation in one file, with no edit to opfbench.

A plugin is a Python module (a file `my_rule.py`, or an installed module) that decorates
a function of the DER's local measurements:

    import numpy as np
    from opfbench.plugins import local_rule

    @local_rule("my-rule", reads=("v", "load"), options={"share": 0.5})
    def my_rule(m, share):
        # Q target in MVAr (positive = injected): a share of the own-bus reactive load,
        # doubled below 0.95 p.u.
        return share * m.load_q_mvar * np.where(m.v_pu < 0.95, 2.0, 1.0)

The function receives `strategies.rules.Measurements` (only what `reads` declares) and
the options as keywords, and returns each DER's Q target (S, n_der) in MVAr. The engine
clips it to the usual limits (reserve k, capability, Algorithm 3, "Q at night"), and
solves a rule that reads |V| or line flows for its closed-loop steady state. It is then a
strategy like the built-in ones: labels with options (`my-rule:share=0.8`), every table, the
report, `snapshot`, `run` and `fault`.

A formulation model is a class decorated with `@formulation` (`formulations.model`): e.g.
a `formulations.models.conic.ConicModel` whose `_network_model` writes its variables,
bus mismatches, objective and constraints. It becomes a strategy of its own, run by the
generic runner (its setpoints AC-evaluated), exactly as a built-in model under
`opfbench/formulations/models/` (`lindistflow.py` is one; tests/test_formulation_plugin.py
loads one from a file).

Loading: `--plugin FILE.py|MODULE` (repeatable) on the commands, or the entry-point group
`opfbench.strategies` of an installed package (loaded when a name is not known, or when
every strategy is listed). A plugin is checked when it loads, before any work: it must
import and register at least one strategy; a rule must have a signature that takes every
declared option and return finite targets of the right shape on a probe; otherwise one
InputError names it. `opfbench run` records each plugin's reference and source digest in
the run's config (a changed plugin is another configuration) and ships the source of a
file plugin to the worker processes, which load it before running (`ensure`); a module
plugin must be importable on the workers. What a plugin registered leaves the registry
with it (`unload`) or when the process state is reset (`state.PROCESS`).
"""

from __future__ import annotations

import hashlib
import importlib
import re
import sys
import types
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from opfbench.errors import InputError
from opfbench.formulations.model import formulation
from opfbench.registry.options import Option
from opfbench.registry.specs import STRATEGIES, forget_source, loading
from opfbench.state import PROCESS
from opfbench.strategies.registration import local_rule

__all__ = ["Option", "PluginSource", "ensure", "formulation", "load", "load_entry_points", "loaded", "local_rule", "unload"]

ENTRY_POINT_GROUP = "opfbench.strategies"


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


_loaded: dict[str, PluginSource] = PROCESS.table("plugins")
_entry_points: dict[str, bool] = PROCESS.table("entry points loaded")


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
        with loading(ref):
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
            with loading(ref):
                imported = importlib.import_module(ref)
            module, text, digest = ref, None, _file_digest(imported)
    except Exception as exc:  # nothing of a plugin that fails half-way stays registered
        forget_source(ref)
        if isinstance(exc, InputError):
            message = str(exc)
            raise InputError(message if message.startswith(f"plugin {ref}") else f"plugin {ref}: {message}") from None
        raise InputError(f"plugin {ref}: cannot import it ({type(exc).__name__}: {exc})") from None
    names = tuple(n for n, s in STRATEGIES.items() if s.source == ref)
    if not names:
        raise InputError(
            f"plugin {ref} registers no strategy: decorate a function with @opfbench.plugins.local_rule(...) "
            "or a model class with @opfbench.plugins.formulation(...)"
        )
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
    """Forget the plugin `ref`: its strategies and models leave the registry (a notebook
    reloading an edited plugin, a study ending, a test cleaning up)."""
    forget_source(ref)
    source = _loaded.pop(ref, None)
    if source is not None:  # its module runs (and registers) anew when loaded next time
        sys.modules.pop(source.module, None)


def loaded(refs: Sequence[str] | None = None) -> tuple[PluginSource, ...]:
    """The loaded plugins (those of `refs` where given), in load order."""
    return tuple(src for ref, src in _loaded.items() if refs is None or ref in refs)


def source_of(strategy_source: str) -> PluginSource | None:
    """The loaded plugin a registered strategy came from (None for opfbench's own)."""
    return _loaded.get(strategy_source)


def load_entry_points() -> None:
    """Load every plugin of the `opfbench.strategies` entry-point group, once per process
    state (`state.PROCESS.reset` forgets them)."""
    if _entry_points:
        return
    _entry_points[ENTRY_POINT_GROUP] = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            load(ep.module)
        except InputError as exc:
            raise InputError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINT_GROUP}): {exc}") from None


def _unload_all() -> None:
    """Every loaded plugin unloaded, entry points to be loaded again on need."""
    for ref in list(_loaded):
        unload(ref)
    _entry_points.clear()


PROCESS.on_reset("plugins", _unload_all)
