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
InputError names it (a plugin that calls `sys.exit` fails the same way). Before a study
writes anything, each plugin rule also runs on the real case's first snapshots
(`probe_case`: its DER kinds, shapes and read-only arrays).

A file plugin is one plugin under any spelling of its path (`good.py`, `./good.py`, its
absolute path). Its fingerprint (`PluginSource.digest`) covers its source and what its
behaviour depends on that opfbench can see: the modules it imports from outside the
standard library and installed packages (a helper module beside it), and the files it
opens while it loads and on its probe (a table it reads). Files it opens only later, the
environment and the network are not seen: the run says so in a note. `opfbench run`
records each plugin's reference and fingerprint in the run's config (a changed plugin or
helper is another configuration) and ships the source of a file plugin to the worker
processes, which load it before running and check its fingerprint there (`ensure`); a
module plugin must be importable on the workers. What a plugin registered leaves the
registry with it (`unload`) or when the process state is reset (`state.PROCESS`).
"""

from __future__ import annotations

import hashlib
import importlib
import io
import json
import os
import re
import sys
import sysconfig
import types
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from dataclasses import dataclass
from functools import lru_cache
from importlib.metadata import entry_points, packages_distributions
from pathlib import Path
from typing import TYPE_CHECKING

from opfbench.errors import InputError
from opfbench.formulations.model import formulation
from opfbench.registry.catalog import configuration
from opfbench.registry.options import Option
from opfbench.registry.specs import OPFBENCH, STRATEGIES, forget_source, loading
from opfbench.state import PROCESS
from opfbench.strategies.registration import local_rule

if TYPE_CHECKING:
    from opfbench.scenario import Scenario

__all__ = [
    "Option",
    "PluginSource",
    "canonical_ref",
    "ensure",
    "formulation",
    "load",
    "load_entry_points",
    "loaded",
    "local_rule",
    "probe_case",
    "unload",
]

ENTRY_POINT_GROUP = "opfbench.strategies"


@dataclass(frozen=True)
class PluginSource:
    """A loaded plugin: `ref` (a file plugin's absolute path, or a module name), the module
    it was loaded as, its fingerprint `digest` (the sha256 of its source, combined with
    those of `depends`), the source text of a file plugin (shipped to workers; None for an
    installed module), the strategies it registered, and `depends`: (path, sha256) of each
    local module and file its behaviour was seen to depend on (module docstring)."""

    ref: str
    module: str
    digest: str
    text: str | None
    strategies: tuple[str, ...]
    depends: tuple[tuple[str, str], ...] = ()

    def note(self) -> str:
        """What the fingerprint covers and what it cannot see, for a note at run time."""
        seen = ", ".join(Path(path).name for path, _ in self.depends)
        return (
            f"note: plugin {self.ref} is fingerprinted by its source{' and ' + seen if seen else ''} (a change is another "
            "configuration); files it opens only after loading and probing, the environment and the network are not in "
            "its fingerprint"
        )


_loaded: dict[str, PluginSource] = PROCESS.table("plugins")
_entry_points: dict[str, bool] = PROCESS.table("entry points loaded")


def probe_case(
    labels: Sequence[str], scenario: Scenario, k: float, where: str, settings: Mapping[str, object] | None = None
) -> None:
    """Run each plugin configuration among `labels` on `scenario` — the real case's first
    snapshots, with its DER kinds, shapes and read-only arrays — before a study writes
    anything; InputError naming the plugin, the configuration and `where` otherwise."""
    for label in labels:
        config = configuration(label)
        if config.spec.source == OPFBENCH:
            continue
        try:
            config.run(scenario, k, settings)
        except InputError as exc:
            raise InputError(f"plugin {config.spec.source}: {label} fails on {where}: {exc}") from None


def _digest(text: str | bytes) -> str:
    return hashlib.sha256(text.encode() if isinstance(text, str) else text).hexdigest()


def _is_path(ref: str) -> bool:
    return ref.endswith(".py") or "/" in ref or "\\" in ref


def canonical_ref(ref: str) -> str:
    """The one name of a plugin: a file's absolute path (every spelling of it alike), or
    the module name."""
    return str(Path(ref).resolve()) if _is_path(ref) else ref


# ----- what a plugin's behaviour depends on -------------------------------------------------
_opened: set[str] | None = None  # the files opened while a plugin loads or is probed


def _audit(event: str, args: tuple) -> None:
    if _opened is not None and event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
        _opened.add(os.fsdecode(args[0]))


@lru_cache(maxsize=1)
def _install_audit() -> None:
    sys.addaudithook(_audit)  # cannot be removed: records only while `_opened` is a set


@contextmanager
def _watching() -> Iterator[tuple[set[str], set[str]]]:
    """(modules imported, files opened) while the block runs (nested: the outer's too)."""
    global _opened
    _install_audit()
    before, outer = set(sys.modules), _opened
    _opened = set() if outer is None else outer
    modules: set[str] = set()
    try:
        yield modules, _opened
    finally:
        modules.update(set(sys.modules) - before)
        _opened = outer


@lru_cache(maxsize=1)
def _installed_roots() -> tuple[frozenset[str], tuple[str, ...]]:
    """(top-level names of installed distributions and the standard library, the folders
    they live in): what a plugin's fingerprint leaves to the run's recorded versions."""
    names = frozenset(packages_distributions()) | frozenset(sys.stdlib_module_names) | {"opfbench"}
    paths = {sysconfig.get_path(key) for key in ("stdlib", "platstdlib", "purelib", "platlib")}
    paths |= {sys.prefix, sys.base_prefix, str(Path(__file__).resolve().parent)}
    return names, tuple(str(Path(p).resolve()) for p in paths if p)


_SYSTEM = ("/proc", "/sys", "/dev")  # kernel views, not data: their content changes by itself


def _local(path: str) -> bool:
    """A file of the user's own (not the interpreter's, an installed package's, opfbench's
    or the kernel's)."""
    _, roots = _installed_roots()
    resolved = str(Path(path).resolve())
    return (
        Path(resolved).is_file()
        and "__pycache__" not in resolved
        and not any(resolved == root or resolved.startswith(root + os.sep) for root in (*roots, *_SYSTEM))
    )


def _reachable(module: types.ModuleType) -> set[str]:
    """The modules a plugin module refers to, directly or through its own local modules."""
    names, todo, seen = set(), [module], {id(module)}
    while todo:
        for value in list(vars(todo.pop()).values()):
            owner = getattr(value, "__module__", None)
            target = value if isinstance(value, types.ModuleType) else sys.modules.get(owner) if isinstance(owner, str) else None
            if isinstance(target, types.ModuleType) and id(target) not in seen:
                seen.add(id(target))
                names.add(target.__name__)
                file = getattr(target, "__file__", None)
                if file and _local(file):
                    todo.append(target)
    return names


def _dependencies(module_name: str, modules: set[str], files: set[str], own: str | None) -> tuple[tuple[str, str], ...]:
    """(path, sha256) of the local modules among `modules` and those `module_name` refers
    to, and of the local files among `files` (not `own`, the plugin's file; not compiled
    code), sorted by path."""
    installed, _ = _installed_roots()
    module = sys.modules.get(module_name)
    names = modules | (_reachable(module) if module is not None else set())
    paths = set()
    for name in names:
        file = getattr(sys.modules.get(name), "__file__", None)
        if file and name.partition(".")[0] not in installed and not name.startswith("opfbench_plugin_") and _local(file):
            paths.add(str(Path(file).resolve()))
    paths |= {str(Path(f).resolve()) for f in files if _local(f) and not f.endswith((".pyc", ".so"))}
    paths.discard(own or "")
    return tuple((path, _digest(Path(path).read_bytes())) for path in sorted(paths))


def _fingerprint(source: str, depends: tuple[tuple[str, str], ...]) -> str:
    """A plugin's digest: its source's sha256, combined with its dependencies' (where it has any)."""
    return source if not depends else _digest(json.dumps([source, [list(d) for d in depends]]))


# ----- loading ---------------------------------------------------------------------------------
@contextmanager
def _quiet_import(ref: str) -> Iterator[None]:
    """Run a plugin's import with its printed output held back (passed on afterwards); a
    `sys.exit` in it is the plugin's failure, named with what it printed (a script given
    as a plugin prints its own usage)."""
    held = io.StringIO()
    try:
        with redirect_stdout(held), redirect_stderr(held):
            yield
    except SystemExit as exc:
        said = " ".join(held.getvalue().split())
        raise InputError(
            f"plugin {ref}: it exited while being imported (sys.exit({exc.code!r}))"
            + (f", printing: {said[:300]}" if said else "")
            + " — a plugin registers rules, it is not a script to run"
        ) from None
    sys.stderr.write(held.getvalue())  # what it printed (stderr: stdout may be a --json answer)


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
        with loading(ref), _quiet_import(ref):
            exec(compile(text, filename, "exec"), module.__dict__)
    except BaseException:
        sys.modules.pop(module_name, None)
        raise
    return module_name


def load(ref: str) -> PluginSource:
    """Load the plugin `ref` (a .py file path, or an importable module name) and check it;
    InputError naming it if it cannot be loaded or registers no (valid) strategy. A file
    plugin is known by its absolute path (`canonical_ref`): any spelling loads it once."""
    given, ref = ref, canonical_ref(ref)
    if ref in _loaded:
        return _loaded[ref]
    own = None
    try:
        with _watching() as (modules, files):
            if _is_path(ref):
                path = Path(ref)
                if not path.is_file():
                    raise InputError(f"plugin {given}: no such file")
                try:
                    text = path.read_text(encoding="utf-8")
                except (OSError, UnicodeDecodeError) as exc:
                    raise InputError(f"plugin {given}: cannot read it ({exc})") from None
                module, own, source = _exec_text(ref, text, ref), ref, _digest(text)
            else:
                with loading(ref), _quiet_import(ref):
                    imported = importlib.import_module(ref)
                module, text, source = ref, None, _file_digest(imported)
                own = getattr(imported, "__file__", None)
        depends = _dependencies(module, modules, files, own and str(Path(own).resolve()))
    except Exception as exc:  # nothing of a plugin that fails half-way stays registered
        forget_source(ref)
        if isinstance(exc, InputError):
            message = str(exc).replace(f"plugin {ref}", f"plugin {given}")
            raise InputError(message if message.startswith(f"plugin {given}") else f"plugin {given}: {message}") from None
        raise InputError(f"plugin {given}: cannot import it ({type(exc).__name__}: {exc})") from None
    names = tuple(n for n, s in STRATEGIES.items() if s.source == ref)
    if not names:
        raise InputError(
            f"plugin {given} registers no strategy: decorate a function with @opfbench.plugins.local_rule(...) "
            "or a model class with @opfbench.plugins.formulation(...)"
        )
    _loaded[ref] = PluginSource(ref, module, _fingerprint(source, depends), text, names, depends)
    return _loaded[ref]


def _file_digest(module: types.ModuleType) -> str:
    file = getattr(module, "__file__", None)
    return _digest(Path(file).read_bytes()) if file and Path(file).is_file() else ""


def ensure(sources: Sequence[PluginSource]) -> None:
    """Load plugins in a worker process as the run's main process loaded them: a file
    plugin from its shipped text, a module by name; InputError if its fingerprint there
    (its source, the modules and files it depends on) is not the one the run recorded. A
    plugin held from an earlier run in another version is loaded anew."""
    for src in sources:
        held = _loaded.get(src.ref)
        if held is not None and held.digest == src.digest:
            continue
        if held is not None:
            unload(src.ref)
        if src.text is not None:
            with _watching() as (modules, files):
                module = _exec_text(src.ref, src.text, src.ref)
            digest = _fingerprint(_digest(src.text), _dependencies(module, modules, files, src.ref))
        else:
            digest = load(src.ref).digest
        if src.digest and digest != src.digest:
            unload(src.ref)
            raise InputError(
                f"plugin {src.ref}: its source or a module or file it depends on differs on this worker from the run's "
                f"(fingerprint {digest[:12]} ≠ {src.digest[:12]})"
            )
        _loaded[src.ref] = src


def unload(ref: str) -> None:
    """Forget the plugin `ref`: its strategies and models leave the registry (a notebook
    reloading an edited plugin, a study ending, a test cleaning up)."""
    ref = canonical_ref(ref)
    forget_source(ref)
    source = _loaded.pop(ref, None)
    if source is not None:  # its module runs (and registers) anew when loaded next time
        sys.modules.pop(source.module, None)


def loaded(refs: Sequence[str] | None = None) -> tuple[PluginSource, ...]:
    """The loaded plugins (those of `refs`, any spelling, where given), in load order."""
    wanted = None if refs is None else {canonical_ref(r) for r in refs}
    return tuple(src for ref, src in _loaded.items() if wanted is None or ref in wanted)


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
