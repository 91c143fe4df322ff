"""Imports go down the layers only: a module imports modules of its own layer or of the
layers below it, never above (nothing below `commands/` imports it). This table is the one
statement of the order (the README says it in words).
Every import counts — module level, inside a function (lazy), under TYPE_CHECKING.

The layer order is written once, here. A new module or package joins by adding its dotted
name to the right layer (a name covers its submodules); a module that no layer names fails
the test, so the table cannot silently fall behind the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "opfbench"

# lowest first: (layer, the modules and packages in it)
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "foundation",
        (
            "opfbench",
            "opfbench.errors",
            "opfbench.jsonio",
            "opfbench.parquetio",
            "opfbench.digests",
            "opfbench.exact",
            "opfbench.threads",
            "opfbench.timing",
            "opfbench.folders",
            "opfbench.state",
        ),
    ),
    ("network", ("opfbench.network", "opfbench.capability", "opfbench.multiphase")),
    ("cases", ("opfbench.io", "opfbench.cases")),
    ("powerflow", ("opfbench.powerflow",)),
    ("records", ("opfbench.scenario", "opfbench.result", "opfbench.schema")),
    ("specs", ("opfbench.registry.options", "opfbench.registry.references", "opfbench.registry.specs")),
    ("strategies", ("opfbench.strategies",)),
    ("learned", ("opfbench.learned",)),
    ("formulations", ("opfbench.formulations",)),
    ("registry", ("opfbench.registry", "opfbench.plugins")),
    ("data", ("opfbench.data", "opfbench.forecasting")),
    ("study", ("opfbench.study",)),
    ("dynamics", ("opfbench.dynamics",)),
    ("report", ("opfbench.report",)),
    ("api", ("opfbench.api",)),
    ("commands", ("opfbench.commands", "opfbench.cli", "opfbench.__main__")),
    ("bench", ("opfbench.bench",)),
)


def layer_of(module: str) -> int | None:
    """Index in LAYERS of the longest name covering `module` (the bare package name covers
    only its own `__init__`), or None."""
    best, depth = None, -1
    for index, (_, names) in enumerate(LAYERS):
        for name in names:
            covers = module == name or (name != "opfbench" and module.startswith(name + "."))
            if covers and name.count(".") > depth:
                best, depth = index, name.count(".")
    return best


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    path = PACKAGE.parent / Path(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def imported(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, module) of every opfbench module `path` imports, relative imports resolved."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # `from opfbench.x import y` may name a submodule y: then y's layer counts
            out += [(node.lineno, f"{base}.{a.name}" if _is_module(f"{base}.{a.name}") else base) for a in node.names]
    return [(line, name) for line, name in out if name == "opfbench" or name.startswith("opfbench.")]


def violations(paths: list[Path]) -> list[str]:
    bad = []
    for path in paths:
        module = module_name(path)
        own = layer_of(module)
        if own is None:
            bad.append(f"{module}: in no layer — add it to LAYERS in tests/test_layers.py")
            continue
        for line, target in imported(path, module):
            theirs = layer_of(target)
            if theirs is None:
                bad.append(f"{module}:{line} imports {target}, which is in no layer")
            elif theirs > own:
                bad.append(f"{module}:{line} ({LAYERS[own][0]}) imports {target} ({LAYERS[theirs][0]}), a layer above")
    return bad


def test_every_import_goes_down_the_layers():
    bad = violations(sorted(PACKAGE.rglob("*.py")))
    assert not bad, "\n".join(bad)


def test_every_layer_name_is_a_module_or_a_package_to_come():
    """A typo in the table would leave modules unchecked; `opfbench.plugins` is announced
    (LAYOUT) and may not exist yet."""
    announced = {"opfbench.plugins"}
    for _, names in LAYERS:
        for name in names:
            assert name in announced or _is_module(name), name


@pytest.mark.parametrize(
    "source, expected",
    [
        ("from opfbench.commands.arguments import fraction\n", "(strategies) imports opfbench.commands.arguments (commands)"),
        ("def f():\n    from opfbench.report import page\n", "(strategies) imports opfbench.report"),
        ("from ..study import config\n", "(strategies) imports opfbench.study"),
        ("import opfbench.registry\n", "(strategies) imports opfbench.registry (registry)"),
    ],
)
def test_the_check_sees_an_upward_import(tmp_path, monkeypatch, source, expected):
    """What the table forbids is found, however it is written (a check that cannot fail
    proves nothing)."""
    package = tmp_path / "opfbench"
    (package / "strategies").mkdir(parents=True)
    path = package / "strategies" / "probe.py"
    path.write_text(source)
    monkeypatch.setattr(__import__(__name__, fromlist=["PACKAGE"]), "PACKAGE", package)
    found = violations([path])
    assert len(found) == 1 and expected in found[0], found


def test_every_lazily_exported_name_resolves():
    """A package that loads its names on first use (`__getattr__` over module names written
    as text) exports exactly what resolves: a renamed module fails here, not in a user's
    import (the import lines these packages hide from the check above are their own
    submodules', in their own layer)."""
    import importlib

    lazy = [p for p in sorted(PACKAGE.rglob("__init__.py")) if "def __getattr__" in p.read_text()]
    assert lazy, "no lazily exporting package found: the check would prove nothing"
    for path in lazy:
        package = importlib.import_module(module_name(path))
        for name in package.__all__:
            assert getattr(package, name) is not None, f"{package.__name__}.{name}"
