"""The tests' own layout, one way: test modules (`tests/test_*.py`) beside `conftest.py`
(the shared fixtures); helpers in the `tests/support/` package, always imported as
`from tests.support.<module> import <name>`; no test imports another test module or the
conftest, and no helper holds a fixture or a test."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent
SUPPORT = TESTS / "support"
LOCAL_NAMES = {p.stem for p in TESTS.rglob("*.py")} | {"support", "tests"}


def _imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, module, imported names) of every import statement in `path`; module is
    "." + name for relative imports."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            out.append((node.lineno, "." * node.level + (node.module or ""), [a.name for a in node.names]))
    return out


def _violations(path: Path) -> list[str]:
    """What breaks the import rule in `path`, one "file:line: what" each."""
    where = path.relative_to(TESTS.parent) if path.is_relative_to(TESTS) else path.name
    bad = []
    for line, module, names in _imports(path):
        top = module.split(".")[0]
        if module.startswith("."):
            bad.append(f"{where}:{line}: relative import {module!r}")
        elif top == "tests":
            parts = module.split(".")
            if len(parts) < 3 or parts[1] != "support" or not names:
                bad.append(f"{where}:{line}: import {module!r} — helpers come as `from tests.support.<module> import <name>`")
        elif top in LOCAL_NAMES:
            bad.append(f"{where}:{line}: bare import of the test-tree module {module!r}")
    return bad


def test_the_test_tree_holds_only_tests_conftest_and_support():
    top = {p.name for p in TESTS.glob("*.py")}
    assert {name for name in top if not name.startswith("test_")} == {"__init__.py", "conftest.py"}
    assert (SUPPORT / "__init__.py").is_file()
    assert not [p for p in SUPPORT.rglob("*.py") if p.name.startswith("test_")]


def test_helpers_are_imported_one_way_and_no_test_imports_another():
    bad = [v for path in sorted(TESTS.rglob("*.py")) for v in _violations(path)]
    assert not bad, "\n".join(bad)


def test_helpers_define_no_fixtures_or_tests():
    bad = []
    for path in sorted(SUPPORT.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                decorators = [ast.unparse(d) for d in node.decorator_list]
                if node.name.startswith("test_") or any("fixture" in d for d in decorators):
                    bad.append(f"{path.relative_to(TESTS.parent)}:{node.lineno}: {node.name}")
    assert not bad, "fixtures belong in tests/conftest.py, tests in tests/test_*.py:\n" + "\n".join(bad)


def test_the_check_sees_each_kind_of_violation(tmp_path):
    """The import rule flags what it should (a check that cannot fail proves nothing)."""
    sample = tmp_path / "sample.py"
    sample.write_text(
        "from tests.test_matpower import GOOD\n"
        "from pandapower_oracle import pandapower_pf\n"
        "import tests.support.feeders\n"
        "from . import conftest\n"
        "from tests.support.feeders import radial_feeder\n"
        "import numpy\n"
    )
    found = [v.split(": ", 1)[0].rsplit(":", 1)[1] for v in _violations(sample)]
    assert found == ["1", "2", "3", "4"]
