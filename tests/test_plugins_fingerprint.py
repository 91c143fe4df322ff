"""What a plugin is: its source and what its behaviour depends on (a helper module it
imports, a table it reads), one plugin under any spelling of its path, each rule name
registered once — so a resume never mixes two versions of a plugin's code."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from opfbench import plugins
from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.study.config import StudyConfig
from opfbench.study.run_family import run_study

pytestmark = pytest.mark.usefixtures("isolated_registry")
PERIOD = {"period": "2016-06-28T10:00..2016-06-28T12:00", "step_minutes": 30.0, "forecast": ["off"]}


def _run(plugin: str, strategy: str, out: Path) -> str:
    """A small study of one plugin rule (the library's run: the CLI's checks, no report);
    returns its notes."""
    plugins.load(plugin)
    config = StudyConfig.build(cases=["paper33"], strategies=[strategy], ks=[0.0], night_modes=["connected"], **PERIOD)
    return "\n".join(run_study(config, out, workers=1).notes)


def _tasks(out: Path) -> list[int]:
    return sorted(p.stat().st_mtime_ns for p in (out / "tasks").glob("*.parquet"))


def _write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text))
    return path


def _helped(folder: Path, helper: str) -> Path:
    """A plugin whose gain comes from a helper module beside it and whose offset from a
    table it reads when it loads."""
    _write(folder / f"{helper}.py", "GAIN = 5.0\n")
    _write(folder / "offset.csv", "0.0\n")
    return _write(
        folder / "helped.py",
        f"""
        import sys
        from pathlib import Path

        import numpy as np

        sys.path.insert(0, str(Path(__file__).parent))
        import {helper}
        from opfbench.plugins import local_rule

        OFFSET = float(np.loadtxt(Path(__file__).parent / "offset.csv"))


        @local_rule("helped", reads=("v",))
        def helped(m):
            return (OFFSET - {helper}.GAIN * (m.v_pu - 1.0)) * m.s_rated_mva
        """,
    )


def _forget(source: plugins.PluginSource, *modules: str) -> None:
    """As a new process would start: the plugin and its helper modules not yet imported."""
    plugins.unload(source.ref)
    for name in modules:
        sys.modules.pop(name, None)


def test_a_helper_module_or_table_edited_before_a_resume_is_another_configuration(tmp_path):
    plugin, out = str(_helped(tmp_path, "gain_helper")), tmp_path / "run"
    err = _run(plugin, "helped", out)
    assert "gain_helper.py" in err and "offset.csv" in err  # what the fingerprint covers
    assert "files it opens only after loading and probing" in err  # and what it cannot see
    for name, edited in (("gain_helper.py", "GAIN = 9.0\n"), ("offset.csv", "0.01\n")):
        original = (tmp_path / name).read_text()
        (tmp_path / name).write_text(edited)
        _forget(plugins.load(plugin), "gain_helper")
        with pytest.raises(InputError, match=r"holds a run of another configuration \(differs in: plugin_digests\)"):
            _run(plugin, "helped", out)
        (tmp_path / name).write_text(original)
        _forget(plugins.load(plugin), "gain_helper")
    tasks = _tasks(out)
    _run(plugin, "helped", out)  # restored: the same configuration, resumed
    assert _tasks(out) == tasks


def test_the_fingerprint_lists_the_local_modules_and_files_not_installed_ones(tmp_path):
    source = plugins.load(str(_helped(tmp_path, "listed_helper")))
    assert [Path(p).name for p, _ in source.depends] == ["listed_helper.py", "offset.csv"]
    assert source.digest != plugins._digest(Path(source.ref).read_text())  # the source alone is not the fingerprint
    plain = plugins.load(str(Path(__file__).resolve().parents[1] / "docs" / "custom_rule.py"))
    assert plain.depends == () and plain.digest == plugins._digest(Path(plain.ref).read_text())  # numpy, opfbench: versions


def test_one_file_under_two_spellings_is_one_plugin(tmp_path, monkeypatch, capsys):
    _write(
        tmp_path / "good.py",
        "from opfbench.plugins import local_rule\n\n@local_rule('good', reads=('p',))\ndef good(m):\n    return 0 * m.p_mw\n",
    )
    monkeypatch.chdir(tmp_path)
    first, second = plugins.load("good.py"), plugins.load("./good.py")
    assert first is second and first.ref == str(tmp_path / "good.py") and first.strategies == ("good",)
    assert plugins.load(str(tmp_path / "good.py")) is first
    assert main(["strategies", "--plugin", "good.py", "--plugin", "./good.py", "--json"]) == 0
    capsys.readouterr()


def test_a_resume_with_the_plugin_path_spelled_otherwise_resumes(tmp_path, monkeypatch):
    _write(
        tmp_path / "good.py",
        "from opfbench.plugins import local_rule\n\n@local_rule('good', reads=('p',))\ndef good(m):\n    return -0.1 * m.p_mw\n",
    )
    monkeypatch.chdir(tmp_path)
    _run("good.py", "good", Path("run"))
    tasks = _tasks(tmp_path / "run")
    monkeypatch.chdir(tmp_path.parent)
    _run(str(tmp_path / "good.py"), "good", tmp_path / "run")
    assert _tasks(tmp_path / "run") == tasks  # nothing run again


def test_a_plugin_registering_a_name_twice_is_refused(tmp_path):
    path = _write(
        tmp_path / "twice.py",
        """
        from opfbench.plugins import local_rule

        @local_rule("twice", reads=("p",))
        def first(m):
            return 0 * m.p_mw

        @local_rule("twice", reads=("p",))
        def second(m):
            return 0.1 * m.p_mw
        """,
    )
    with pytest.raises(InputError, match=f"plugin {path}: strategy 'twice' is registered twice by"):
        plugins.load(str(path))
    assert "twice" not in {name for src in plugins.loaded() for name in src.strategies}
