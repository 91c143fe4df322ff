"""Every registered strategy runs through the one registry and returns the one record;
configuration labels are parsed, checked and canonical."""

import numpy as np
import pytest

from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.registry.catalog import STRATEGIES, canonical, configuration, get_strategy, run_strategy, specs
from opfbench.registry.references import BASELINE, DEFAULT_RUN, PAPER_OPF, REFERENCE_OPTIMUM
from opfbench.registry.specs import MODELS
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario


def test_the_catalog_lists_every_strategy_once_as_its_declarations_say():
    """What the registry promises, not a count: names unique, in the catalog's order; the
    default grid is the declared one (built-in, not learned, in that order); the reference
    configurations have the kind and role the comparisons need; every formulation model
    that is not the OPF problem's is a strategy of its own with its role; a learned entry
    is one with a fit."""
    entries = specs()
    names = [s.name for s in entries]
    assert len(names) == len(set(names)) and set(names) == set(STRATEGIES)
    assert all(STRATEGIES[n].source == "opfbench" and not STRATEGIES[n].learned for n in DEFAULT_RUN)
    assert [n for n in names if n in DEFAULT_RUN] == list(DEFAULT_RUN)
    assert STRATEGIES[BASELINE].kind == "local" and STRATEGIES[BASELINE].target is not None
    assert {STRATEGIES[n].role for n in (REFERENCE_OPTIMUM, PAPER_OPF)} == {"exact"}
    bounds = sorted((s.bound_rank, s.name) for s in entries if s.bound_rank is not None)
    assert STRATEGIES[bounds[0][1]].role == "relaxation" and STRATEGIES[REFERENCE_OPTIMUM].bound_rank is not None
    for s in entries:
        assert (s.kind == "formulation") == (s.role is not None)
    for model in MODELS.values():
        assert model.serves_problem or (
            STRATEGIES[model.name].role == model.role and STRATEGIES[model.name].kind == "formulation"
        )
    assert all(s.kind == "local" and s.fit_options for s in entries if s.learned)


@pytest.mark.parametrize("name", DEFAULT_RUN)
def test_every_registered_strategy_returns_the_record(name):
    net = load_network("paper33")
    scenario = Scenario.snapshot(net, 1.0, 0.8, 0.9 if STRATEGIES[name].uses_forecast else None)
    res = run_strategy(name, scenario, 0.2)
    assert isinstance(res, StrategyResult)
    assert res.strategy == name and res.k == 0.2
    assert res.q_mvar.shape == (1, len(net.ders))
    assert res.status[0] == "ok" and np.isfinite(res.losses_kw[0])
    assert res.snapshot_json(0)["strategy"] == name


@pytest.mark.parametrize("name", ["no-action", "llma", "lfma", "volt-var", "q-u", "acopf", "socp"])
def test_the_papers_and_the_injecting_rules_never_lose_to_no_action_here(name):
    """At 0.8 × rating on paper33 (voltages 0.91–1.0 p.u.) every rule that injects Q cuts the
    losses below no action's 84.260 kW (pandapower-checked)."""
    res = run_strategy(name, Scenario.snapshot(load_network("paper33"), 1.0, 0.8, 0.9), 0.2)
    assert res.losses_kw[0] <= 84.26 + 1e-3


def test_acopf_paper_pins_the_papers_setup():
    spec = get_strategy("acopf-paper").spec
    assert spec.fixed == {"fallback": "paper", "slack_export": False}
    assert [o.name for o in spec.options] == ["solver"]  # the fast path, or IPOPT on every step
    assert spec.option["solver"].setting == "acopf_solver"  # its default: the run's --acopf-solver
    res = run_strategy("acopf-paper", Scenario.snapshot(load_network("paper33")), 0.0)
    assert res.extra["slack_export"] is False


def test_run_level_setting_is_an_option_default_the_label_overrides():
    config = configuration("acopf")
    assert config.options({"acopf_solver": "ipopt"})["solver"] == "ipopt"
    assert configuration("acopf:solver=auto").options({"acopf_solver": "ipopt"})["solver"] == "auto"
    assert canonical("acopf:solver=auto") == "acopf:solver=auto"  # kept: the run's setting may be another
    assert configuration("acopf:fallback=paper").options({"acopf_solver": "ipopt"})["fallback"] == "paper"
    assert configuration("lfma").options({"acopf_solver": "ipopt"}) == {"safe": False}  # no option takes it


@pytest.mark.parametrize(
    "label, expected",
    [
        ("volt-var", "volt-var"),
        ("volt-var:curve=b", "volt-var"),
        (" volt-var:curve=a ", "volt-var:curve=a"),
        ("volt-var:curve=a,", "volt-var:curve=a"),
        ("volt-var:q=0.25/0/-0.25,v=0.90/1.0/1.10", "volt-var:v=0.9/1/1.1,q=0.25/0/-0.25"),
        ("const-pf:mode=inject,pf=0.900", "const-pf:pf=0.9,mode=inject"),
        ("cosphi-p:pf_min=0.95", "cosphi-p:pf_min=0.95"),
        ("q-u:deadband=TRUE", "q-u:deadband=true"),
        ("acopf:solver=ipopt", "acopf:solver=ipopt"),
        ("volt-var:tol_v_pu=1e-9", "volt-var:tol_v_pu=1e-09"),
    ],
)
def test_labels_are_canonical(label, expected):
    assert canonical(label) == expected
    assert canonical(expected) == expected


@pytest.mark.parametrize(
    "label, message",
    [
        ("nope", "unknown strategy 'nope'"),
        ("volt-varr", "did you mean volt-var"),
        ("volt-var:curve=c", "option curve: 'c' is not one of a, b"),
        ("volt-var:foo=1", "volt-var takes no option foo"),
        ("volt-var:curve", "'curve' is not key=value"),
        ("volt-var:curve=a,curve=b", "option curve given twice"),
        ("volt-var:v=1.0/0.9,q=0/0", "the curve's v values must increase"),
        ("volt-var:v=0.9/1.1,q=1.5/0", "must lie in \\[−1, 1\\]"),
        ("volt-var:v=0.9/1.1", "give both v= and q="),
        ("volt-var:v=0.9/1.0/1.1,q=0.2/0", "same number of points"),
        ("volt-var:curve=a,v=0.9/1.1,q=0.2/0", "give curve= or the points"),
        ("volt-var:v=0.9/nan,q=0/0", "not a decimal number"),
        ("const-pf:pf=0", "a power factor must lie in \\(0, 1\\]"),
        ("const-pf:pf=1.01", "a power factor must lie in \\(0, 1\\]"),
        ("const-pf:mode=both", "not one of absorb, inject"),
        ("cosphi-p:p_start=1", "p_start is a share of P̄"),
        ("q-u:q_max=2", "q_max is per unit of P̄"),
        ("volt-var:step_factor=0", "a step factor lies in \\(0, 1\\]"),
        ("volt-var:max_steps=1.5", "not a whole number"),
        ("q-u:deadband=yes", "not true or false"),
        ("acopf:safe=true", "acopf takes no option safe"),
        ("acopf-paper:fallback=chain", "acopf-paper takes no option fallback"),
    ],
)
def test_bad_labels_are_one_input_error_naming_it(label, message):
    with pytest.raises(InputError, match=message):
        configuration(label)


def test_unknown_strategy_and_option_are_input_errors():
    scenario = Scenario.snapshot(load_network("paper33"))
    with pytest.raises(InputError, match="unknown strategy 'nope'"):
        run_strategy("nope", scenario, 0.0)
    with pytest.raises(InputError, match="takes no option safe"):
        run_strategy("acopf", scenario, 0.0, safe=True)
    with pytest.raises(InputError, match="takes no option fallback"):
        run_strategy("acopf-paper", scenario, 0.0, fallback="chain")
    with pytest.raises(InputError, match="option safe: 'false' is not a bool"):
        run_strategy("llma", scenario, 0.0, safe="false")


def test_a_label_names_its_result():
    res = run_strategy("volt-var:curve=a,", Scenario.snapshot(load_network("paper33")), 0.0)
    assert res.strategy == "volt-var:curve=a"


@pytest.mark.parametrize(
    "label, key",
    [("volt-var:curve=b,curve=a", "curve"), ("volt-var:curve=a,curve=a", "curve"), ("q-u:q_max=0.33,q_max=0.2", "q_max")],
)
def test_an_option_given_twice_is_refused_even_when_one_value_is_the_default(label, key):
    with pytest.raises(InputError, match=f"option {key} given twice"):
        configuration(label)


@pytest.mark.parametrize("label", ["q-u:deadband=true,v=0.9/1.1,q=0.3/-0.3", "q-u:q_max=0.2,v=0.9/1.1,q=0.3/-0.3"])
def test_q_u_points_with_the_characteristics_options_are_refused_not_ignored(label):
    with pytest.raises(InputError, match="the points replace it"):
        configuration(label)
