"""Your own rule in one file: the worked example (docs/custom_rule.py) loads and runs as a
strategy like the built-in ones; a bad plugin is one InputError naming it, before any
work; a rule's NaN at run time is a named status and the run goes on; the entry-point
group loads plugins of installed packages."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from opfbench import plugins
from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.registry.catalog import STRATEGIES, configuration, run_strategy, spec
from opfbench.result import OK, RULE_NON_FINITE
from opfbench.scenario import Scenario

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "custom_rule.py"
pytestmark = pytest.mark.usefixtures("isolated_registry")


def _plugin(tmp_path: Path, body: str, name: str = "my_rule.py") -> str:
    path = tmp_path / name
    path.write_text("import numpy as np\nfrom opfbench.plugins import local_rule\n\n" + textwrap.dedent(body))
    return str(path)


def test_the_worked_example_is_a_closed_loop_rule_with_options():
    source = plugins.load(str(EXAMPLE))
    assert source.strategies == ("droop",) and source.text == EXAMPLE.read_text() and len(source.digest) == 64
    entry = spec("droop")
    assert entry.kind == "local" and entry.reads == ("v",) and entry.closed_loop and entry.uses_forecast
    assert {"gain", "v_ref", "safe", "max_steps", "step_factor"} <= set(entry.option)
    assert configuration("droop:gain=8.0,v_ref=1").label == "droop:gain=8"
    with pytest.raises(InputError, match="option gain: a droop gain is ≥ 0"):
        configuration("droop:gain=-1")
    net = load_network("paper33")
    res = run_strategy("droop:gain=8", Scenario.snapshot(net), 0.2)
    assert res.status[0] == OK and res.strategy == "droop:gain=8" and res.extra["residual_mvar"][0] <= 1e-7
    v = res.vm[0, net.der_bus]
    limit = 0.8 * Scenario.snapshot(net).qmax_mvar()[0]
    np.testing.assert_allclose(res.q_mvar[0], np.clip(-8 * (v - 1) * net.der_s_mva, -limit, limit), atol=1e-6)


@pytest.mark.parametrize(
    "body, message",
    [
        ("import no_such_module_anywhere\n", "cannot import it \\(ModuleNotFoundError"),
        ("def broken(:\n", "cannot import it \\(SyntaxError"),
        ("x = 1\n", "registers no strategy"),
        (
            """
            @local_rule("r1", reads=("v",))
            def r1():
                return 0
            """,
            "must take the measurements as its first argument",
        ),
        (
            """
            @local_rule("r2", reads=("v",), options={"gain": 1.0})
            def r2(m):
                return m.v_pu
            """,
            "takes no argument gain for its declared option",
        ),
        (
            """
            @local_rule("r3", reads=("v",))
            def r3(m, extra):
                return m.v_pu
            """,
            "extra are neither options nor defaulted",
        ),
        (
            """
            @local_rule("r4", reads=("v",))
            def r4(m):
                return m.v_pu[:, 0]
            """,
            "returned shape \\(3,\\); it must return \\(S, n_der\\) = \\(3, 2\\)",
        ),
        (
            """
            @local_rule("r5", reads=("v",))
            def r5(m):
                return np.where(m.v_pu < 0.92, np.nan, 0.0)
            """,
            "returned NaN or inf on a probe",
        ),
        (
            """
            @local_rule("lfma", reads=("v",))
            def mine(m):
                return 0 * m.v_pu
            """,
            "strategy name 'lfma' is taken \\(by opfbench\\)",
        ),
        (
            """
            @local_rule("r6", reads=("voltage",))
            def r6(m):
                return 0 * m.v_pu
            """,
            "unknown measurement\\(s\\) voltage",
        ),
        (
            """
            @local_rule("r7", reads=("p",))
            def r7(m):
                return 0 * m.v_pu
            """,
            "reads v_pu but does not declare 'v'",
        ),
        (
            """
            @local_rule("r8", reads=("v",), options={"safe": True})
            def r8(m, safe):
                return 0 * m.v_pu
            """,
            "option name 'safe' is the engine's",
        ),
        (
            """
            @local_rule("r9", reads=("v",))
            def r9(m):
                return "high"
            """,
            "rule 'r9' returned <U4 values; a Q target is real numbers",
        ),
        (
            """
            from opfbench.strategies.rules import Targets

            @local_rule("r11", reads=("v",))
            def r11(m):
                return Targets(0 * m.v_pu, m.p_rated_mw * (m.v_pu < 1.05))
            """,
            "caps active power but is not declared a rule that curtails",
        ),
        (
            """
            @local_rule("Bad Name", reads=("v",))
            def r10(m):
                return 0 * m.v_pu
            """,
            "strategy name 'Bad Name' must be lower-case",
        ),
    ],
)
def test_a_bad_plugin_is_one_input_error_naming_it_and_leaves_nothing_registered(tmp_path, body, message):
    before = set(STRATEGIES)
    ref = _plugin(tmp_path, body)
    with pytest.raises(InputError, match=message) as err:
        plugins.load(ref)
    assert str(err.value).startswith(f"plugin {ref}")
    assert set(STRATEGIES) == before


def test_a_missing_plugin_file_or_module_is_named():
    with pytest.raises(InputError, match="plugin nowhere/rule.py: no such file"):
        plugins.load("nowhere/rule.py")
    with pytest.raises(InputError, match="plugin no_such_plugin_module: cannot import it"):
        plugins.load("no_such_plugin_module")


@pytest.mark.parametrize("command", ["run", "snapshot", "strategies", "fault"])
def test_cli_refuses_a_bad_plugin_before_any_work(tmp_path, capsys, command):
    ref = _plugin(tmp_path, "import no_such_module_anywhere\n")
    out = tmp_path / "out"
    argv = {
        "run": ["run", "--out", str(out), "--plugin", ref],
        "snapshot": ["snapshot", "paper33", "--strategy", "llma", "--plugin", ref],
        "strategies": ["strategies", "--plugin", ref],
        "fault": ["fault", "paper33", "--fault-bus", "18", "--plugin", ref],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"plugin {ref}: cannot import it" in err and "Traceback" not in err
    assert not out.exists()


NAN_RULE = """
@local_rule("nan-above", reads=("v",), options={"threshold": 10.0})
def nan_above(m, threshold):
    return np.where((m.v_pu > threshold).all(axis=1, keepdims=True), np.nan, 0.0 * m.v_pu)
"""


def test_a_rule_that_gives_nan_at_run_time_is_a_named_status_and_the_others_go_on(tmp_path):
    plugins.load(_plugin(tmp_path, NAN_RULE))
    net = load_network("paper33")
    scenario = Scenario(net, [0.3, 1.0, 1.5], np.full((3, 5), 0.3))  # light load: the highest voltages
    res = run_strategy("nan-above:threshold=0.98", scenario, 0.0)
    assert list(res.status) == [RULE_NON_FINITE, OK, OK]
    assert np.isnan(res.q_mvar[0]).all() and np.isnan(res.losses_kw[0]) and np.isfinite(res.losses_kw[1:]).all()


def test_an_open_loop_rule_that_gives_nan_is_named_too(tmp_path):
    body = """
    @local_rule("nan-p", reads=("p",), options={"above": 10.0})
    def nan_p(m, above):
        return np.where(m.p_mw > above, np.inf, -0.1 * m.p_mw)
    """
    plugins.load(_plugin(tmp_path, body))
    net = load_network("paper33")
    res = run_strategy("nan-p:above=0.5", Scenario(net, [1.0, 1.0], [[0.3] * 5, [0.3, 0.3, 0.6, 0.3, 0.3]]), 0.0)
    assert list(res.status) == [OK, RULE_NON_FINITE] and res.power_flows.tolist() == [1, 1]


def test_a_plugin_rule_may_cap_active_power_where_it_says_it_curtails(tmp_path):
    """A plugin's own Volt-Watt — `curtails=True`, returning Q targets and a cap (MW) — runs on
    the engine as the built-in one does, reactive priority included."""
    body = """
    from opfbench.strategies.rules import Targets

    @local_rule("my-vw", reads=("v",), options={"v_full": 1.06, "v_zero": 1.1}, curtails=True)
    def my_vw(m, v_full, v_zero):
        share = np.clip((v_zero - m.v_pu) / (v_zero - v_full), 0.0, 1.0)
        return Targets(np.zeros(m.shape), share * m.p_rated_mw)
    """
    plugins.load(_plugin(tmp_path, body))
    assert spec("my-vw").curtails and {o.name for o in spec("my-vw").options} >= {"safe", "priority"}
    scenario = Scenario.snapshot(load_network("paper33"), 0.0, 1.0)
    mine, built_in = run_strategy("my-vw", scenario, 0.0), run_strategy("volt-watt", scenario, 0.0)
    assert mine.curtailed_mw is not None and built_in.curtailed_mw is not None and mine.curtailed_mw.sum() > 1e-3
    np.testing.assert_allclose(mine.curtailed_mw, built_in.curtailed_mw, atol=1e-6)


def test_the_entry_point_group_loads_an_installed_plugin(tmp_path, monkeypatch):
    module = tmp_path / "installed_rule.py"
    module.write_text(
        textwrap.dedent(
            """
            from opfbench.plugins import local_rule

            @local_rule("installed", reads=("p",), options={"share": 0.1})
            def installed(m, share):
                return share * m.p_mw
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))

    class EntryPoint:
        name, value, module = "installed", "installed_rule", "installed_rule"

    monkeypatch.setattr(plugins, "entry_points", lambda group: [EntryPoint()] if group == plugins.ENTRY_POINT_GROUP else [])
    monkeypatch.setattr(plugins, "_entry_points", {})  # not loaded yet in this process
    assert spec("installed").source == "installed_rule"  # loaded on first need
    res = run_strategy("installed:share=0.2", Scenario.snapshot(load_network("paper33")), 0.0)
    assert res.status[0] == OK and res.q_mvar[0] == pytest.approx(0.2 * 0.8 * 0.6, abs=1e-12)
    plugins.unload("installed_rule")


def test_rule_non_finite_steps_are_counted_under_their_own_name_in_the_summary_and_report(tmp_path):
    ref = _plugin(tmp_path, NAN_RULE)
    out = tmp_path / "run"
    argv = ["run", "--plugin", ref, "--strategies", "no-action", "nan-above:threshold=0.5", "--k", "0"]
    argv += ["--night-modes", "connected", "--forecast", "off", "--period", "2016-06-28T10:00..2016-06-28T11:00"]
    assert main([*argv, "--step-minutes", "10", "--workers", "1", "--quiet", "--out", str(out)]) == 0
    import pandas as pd

    row = pd.read_csv(out / "summary.csv").set_index("strategy").loc["nan-above:threshold=0.5"]
    assert (row.steps, row.rule_non_finite_steps, row.pf_diverged_steps, row.pf_converged_steps) == (6, 6, 0, 0)
    html = (out / "report.html").read_text()
    assert "rule-non-finite, the rule gave NaN or inf: no setpoint: 6 steps" in html
    assert "pf-diverged, the power flow did not converge" not in html  # not counted as what it is not
