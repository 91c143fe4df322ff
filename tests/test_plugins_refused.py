"""A plugin that cannot run is refused before anything is written: one that fails only on
the real case (a DER kind, a shape, an in-place write, an undeclared read the made-up probe
does not show), one that calls `sys.exit`, one whose option check raises, one whose extra
column is the steps table's own; a rule's complex or non-numeric answer is refused, never
cast; work-sizing options are bounded."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from opfbench import plugins
from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.registry.catalog import configuration, run_strategy
from opfbench.scenario import Scenario

pytestmark = pytest.mark.usefixtures("isolated_registry")
CASE = "case33bw?der=18:PV:0.5,25:inverter:0.5,30:DFIG:0.6"  # the probe's kinds are PV and DFIG
RUN = ["--case", CASE, "--k", "0", "--night-modes", "connected", "--forecast", "off"]
RUN += ["--period", "2016-06-28T10:00..2016-06-28T11:00", "--step-minutes", "30", "--workers", "1", "--quiet"]


def _plugin(tmp_path: Path, body: str, name: str = "rule.py") -> str:
    path = tmp_path / name
    path.write_text("import numpy as np\nfrom opfbench.plugins import local_rule\n" + textwrap.dedent(body))
    return str(path)


REAL_CASE_ONLY = {
    "a DER kind the probe lacks": (
        """
        @local_rule("kinds", reads=("p",))
        def kinds(m):
            if (m.kinds == "inverter").any():
                raise ValueError("no inverters here")
            return 0 * m.p_mw
        """,
        "ValueError: no inverters here",
    ),
    "a shape fixed to the probe's": (
        """
        @local_rule("fixed", reads=("p",))
        def fixed(m):
            return np.zeros((3, 2))
        """,
        "returned shape (3, 2)",
    ),
    "an in-place write": (
        """
        @local_rule("inplace", reads=("v",))
        def inplace(m):
            v = m.v_pu
            v -= 1.0
            return -v * m.s_rated_mva
        """,
        "read-only",
    ),
    "an undeclared read on more DER": (
        """
        @local_rule("sneaky", reads=("p",))
        def sneaky(m):
            return m.load_q_mvar if m.shape[1] > 2 else 0 * m.p_mw
        """,
        "does not declare 'load'",
    ),
}


@pytest.mark.parametrize("what", list(REAL_CASE_ONLY))
def test_a_plugin_failing_only_on_the_real_case_is_refused_before_anything_is_written(what, tmp_path, capsys):
    body, message = REAL_CASE_ONLY[what]
    ref = _plugin(tmp_path, body)
    name = body.split('"')[1]
    out = tmp_path / "run"
    assert main(["run", "--plugin", ref, "--strategies", "no-action", name, *RUN, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    where = "its probe" if what == "an in-place write" else f"{CASE}'s first steps"  # the probe's arrays are read-only too
    assert f"plugin {ref}: " in err and message in err and "Traceback" not in err and err.count("\n") == 1
    assert where == "its probe" or f"{name} fails on {where}" in err
    assert not out.exists()  # no manifest, no tasks/, no folder


def test_sys_exit_in_a_plugin_is_the_plugins_failure_never_the_commands_exit(tmp_path, capsys):
    quits = _plugin(tmp_path, "import sys\nsys.exit(0)\n", "quits.py")
    assert main(["strategies", "--plugin", quits]) == 2
    assert f"plugin {quits}: it exited while being imported (sys.exit(0))" in capsys.readouterr().err
    script = _plugin(
        tmp_path,
        """
        import argparse
        parser = argparse.ArgumentParser(prog="tool")
        parser.add_argument("--input", required=True)
        parser.parse_args()
        """,
        "script.py",
    )
    out = tmp_path / "run"
    assert main(["run", "--plugin", script, "--strategies", "no-action", *RUN, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"plugin {script}: it exited while being imported (sys.exit(2)), printing: usage: tool" in err
    assert not out.exists()
    # inside a rule: the rule's failure, named
    plugins.load(
        _plugin(
            tmp_path,
            '@local_rule("leaves", reads=("p",))\ndef leaves(m):\n    import sys\n    sys.exit(0) if (m.kinds == "inverter").any() else None\n    return 0 * m.p_mw\n',
            "leaves.py",
        )
    )
    with pytest.raises(InputError, match=r"rule 'leaves' failed: SystemExit: 0"):
        run_strategy("leaves", Scenario.snapshot(load_network(CASE)), 0.0)


def test_an_option_check_that_raises_is_the_plugins_error(tmp_path):
    ref = _plugin(
        tmp_path,
        """
        from opfbench.plugins import Option

        @local_rule("checked", reads=("p",), options={"gain": Option("gain", 1.0, "a gain", check=lambda v: {}["limits"][v])})
        def checked(m, gain):
            return -gain * m.p_mw
        """,
    )
    with pytest.raises(InputError, match=r"option gain's default 1: its check failed on 1 \(KeyError: 'limits'\)"):
        plugins.load(ref)


def test_an_extra_column_that_is_the_steps_tables_own_is_refused_before_any_work(tmp_path, capsys):
    ref = _plugin(
        tmp_path,
        """
        @local_rule("clash", reads=("p",), columns={"losses_kw": "my own losses"})
        def clash(m):
            return 0 * m.p_mw
        """,
    )
    out = tmp_path / "run"
    assert main(["run", "--plugin", ref, "--strategies", "clash", *RUN, "--out", str(out)]) == 2
    assert "declares the extra column 'losses_kw', one of the steps table's own" in capsys.readouterr().err
    assert not out.exists()


def test_a_complex_or_textual_target_is_refused_not_cast(tmp_path):
    body = '@local_rule("cplx", reads=("p",), options={"on": 0.0})\ndef cplx(m, on):\n    return m.p_mw * (1 + 1j * on) if on else -m.p_mw\n'
    plugins.load(_plugin(tmp_path, body))
    scenario = Scenario.snapshot(load_network(CASE))
    assert run_strategy("cplx", scenario, 0.0).status[0] == "ok"
    with pytest.raises(InputError, match="rule 'cplx' returned complex128 values; a Q target is real numbers"):
        run_strategy("cplx:on=0.5", scenario, 0.0)
    with pytest.raises(InputError, match="returned complex128 values"):  # a zero imaginary part is no real number either
        run_strategy("cplx:on=1e-300", scenario, 0.0)
    plugins.load(
        _plugin(
            tmp_path,
            '@local_rule("words", reads=("p",), options={"on": 0.0})\ndef words(m, on):\n    return m.p_mw.astype(str) if on else m.p_mw\n',
            "words.py",
        )
    )
    with pytest.raises(InputError, match="rule 'words' returned <U32 values"):
        run_strategy("words:on=1", scenario, 0.0)


def test_the_closed_loops_step_count_is_bounded(tmp_path):
    with pytest.raises(InputError, match=r"option max_steps: lies in 0..1000"):
        configuration("volt-var:max_steps=2000000000")
    plugins.load(
        _plugin(tmp_path, '@local_rule("osc", reads=("v",))\ndef osc(m):\n    return np.sign(1 - m.v_pu) * m.s_rated_mva\n')
    )
    with pytest.raises(InputError, match=r"option max_steps: lies in 0..1000"):
        configuration("osc:max_steps=1001")
    assert configuration("osc:max_steps=1000").label == "osc:max_steps=1000"
    np.testing.assert_equal(configuration("osc:max_steps=0").options()["max_steps"], 0)
