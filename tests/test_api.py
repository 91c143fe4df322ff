"""The Python API (`opfbench.api`): the example script in docs/ runs a small study and
reads its tables; bad input raises the CLI's typed errors before any work; a second study
in the same process gets no state from a first one that loaded a plugin; the library
prints nothing, and Ctrl-C stops a study with `Stopped`, not an exit."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from opfbench import api, plugins
from opfbench.errors import InputError
from opfbench.formulations import solves
from opfbench.learned import rules as learned
from opfbench.registry.specs import STRATEGIES
from opfbench.state import PROCESS
from opfbench.study.store import finished_tasks
from tests.support.processes import ROOT, ctrl_c_when

SHORT = {"ks": [0.0], "night_modes": ["connected"], "forecast": ["off"], "period": "2016-06-28T11:00..2016-06-28T12:00"}
DROOP = """
    from opfbench.plugins import local_rule

    @local_rule("api-droop", reads=("v",), options={"gain": 5.0})
    def droop(m, gain):
        return gain * (1.0 - m.v_pu) * m.s_rated_mva
"""


def test_the_example_script_runs_a_study_and_reads_its_tables(tmp_path):
    out = tmp_path / "example"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "api_example.py"), str(out)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("paper33: 33 buses, 5 DER") and "LFMA on one operating point" in lines[1]
    assert sum(line.split()[0] in ("no-action", "lfma", "lindistflow", "acopf") for line in lines) == 8  # 4 strategies × 2 k
    assert "LFMA at k = 0.4: 60 steps" in proc.stdout and (out / "report.html").is_file()
    assert "frontier at k = 0.4: 7 widenings ε of the band, 420 rows" in proc.stdout  # 60 steps × 7 ε
    assert proc.stderr == ""  # the library says nothing on its own


def test_bad_input_raises_the_clis_typed_errors_before_any_work(tmp_path):
    for bad, message in (
        ({"ks": [1.5]}, r"\[0, 1\]"),
        ({"strategies": ["lfma", "nope"]}, "unknown strategy 'nope'"),
        ({"cases": ["nope.m"]}, "nope.m"),
        ({"period": "2016-13-01..2016-13-02"}, "2016-13-01"),
    ):
        with pytest.raises(InputError, match=message):
            api.run_study(**(SHORT | {"strategies": ["no-action"]} | bad), out=tmp_path / "bad")
        assert not (tmp_path / "bad" / "steps.parquet").exists()


def test_a_second_study_gets_no_state_from_a_first_with_a_plugin(tmp_path):
    plugin = tmp_path / "droop.py"
    plugin.write_text(textwrap.dedent(DROOP))
    first = api.run_study(strategies=["no-action", "api-droop"], plugins=[str(plugin)], out=tmp_path / "first", **SHORT)
    assert set(first.summary["strategy"]) == {"no-action", "api-droop"} and (first.summary["not_ok_steps"] == 0).all()
    # what the first study left: no plugin, no strategy of it, no fitted rule, no cached solve
    assert plugins.loaded() == () and "api-droop" not in STRATEGIES
    assert learned._installed == {} and solves._cache.used == 0
    with pytest.raises(InputError, match="unknown strategy 'api-droop'"):
        api.run_study(strategies=["api-droop"], out=tmp_path / "second", **SHORT)
    third = api.run_study(strategies=["no-action"], out=tmp_path / "third", **SHORT)
    assert third.config.plugins == () and set(third.summary["strategy"]) == {"no-action"}
    held = {"strategies", "formulation models", "plugins", "installed learned rules", "cases read", "formulation solves"}
    assert held <= set(PROCESS.names())  # the process's state, declared in one place


SCRIPT = """
import sys
from opfbench import api
from opfbench.errors import Stopped
try:
    api.run_study(strategies=["no-action", "acopf"], ks=[0.0, 0.2, 0.4, 0.6, 0.8], night_modes=["connected"],
                  forecast=["off"], period="2016-06-28T10:00..2016-06-28T11:00", detail=False, out=sys.argv[1])
except Stopped as exc:
    print(f"caught: {exc}")
"""


@pytest.mark.slow  # a fresh process and AC OPF tasks until the first is saved
def test_ctrl_c_stops_a_library_study_with_stopped_not_an_exit(tmp_path):
    out = tmp_path / "run"
    proc, stdout, stderr, _ = ctrl_c_when([sys.executable, "-c", SCRIPT, str(out)], lambda: finished_tasks(out) > 0)
    assert proc.returncode == 0, stderr
    kept = finished_tasks(out)
    assert f"caught: {kept} tasks kept in {out}; rerun the same command to resume" in stdout and stderr == ""
    assert 1 <= kept < 5 and not (out / ".lock").exists()
