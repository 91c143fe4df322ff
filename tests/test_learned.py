"""Learned local rules (issue 21): the families recover rules they can represent, every
fitted curve obeys its slope bound (and the undamped closed loop contracts), the rules stay
within their DER's limits, the params file round-trips and is checked, the training data
hold nothing of the test period, and the perturbed-model case option."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opfbench.cli import main
from opfbench.errors import InputError
from opfbench.io import load_case, load_network, parse_spec
from opfbench.learned import rules as learned
from opfbench.learned.rules import (
    FAMILIES,
    AffineRule,
    Features,
    Ieee1547Rule,
    LearnedParams,
    VoltVarRule,
    fit_rule,
)
from opfbench.powerflow import solve_pf, solve_pf_batch
from opfbench.registry.catalog import configuration, run_strategy
from opfbench.strategies.limits import reactive_limit
from opfbench.strategies.sensitivity import contraction_factor, voltage_sensitivity
from opfbench.study.periods import resolve_period
from opfbench.study.training_checks import check_learned, training_scenario, training_set

TRAIN = "2016-03-01..2016-03-03"  # two days at 15 min (SimBench PV3 outside June)
TEST = "2016-03-03..2016-03-04"


def _random_features(rng: np.random.Generator, n_rows: int, s: np.ndarray) -> Features:
    shape = (n_rows, len(s))
    return Features(
        rng.uniform(0.94, 1.06, shape),
        rng.uniform(0, 1, shape) * s,
        rng.uniform(0, 1, shape),
        rng.uniform(-0.2, 0.5, shape) * s,
        s,
    )


# ----- the families on data they can represent ----------------------------------------------
def test_affine_recovers_a_linear_rule_inside_its_bound():
    rng = np.random.default_rng(1)
    s = np.array([0.5, 1.0, 2.0])
    x = _random_features(rng, 400, s)
    truth = AffineRule()
    truth.coef_ = np.array([[0.3, -0.2, -0.4, 0.5], [1.1, 0.1, -1.2, -0.3], [0.5, 0.0, -0.6, 0.2]])
    y = truth.predict(x)
    fitted = AffineRule().fit(x, y, np.full(3, 10.0), np.ones(y.shape, dtype=bool))
    np.testing.assert_allclose(fitted.coef_, truth.coef_, atol=1e-6)
    # with a tighter bound than the truth's slope, the slope sits on the bound
    bound = np.array([0.1, 0.1, 0.1])
    tight = AffineRule().fit(x, y, bound, np.ones(y.shape, dtype=bool))
    assert np.all(tight.v_slope() <= bound * (1 + 1e-9)) and np.allclose(tight.v_slope(), bound, rtol=1e-6)
    # the droop sign: a rule whose Q rose with its own voltage is not fitted (c ≤ 0)
    rising = AffineRule()
    rising.coef_ = truth.coef_ * np.array([1, 1, -1, 1])
    assert np.all(AffineRule().fit(x, rising.predict(x), np.full(3, 10.0), np.ones(y.shape, dtype=bool)).coef_[:, 2] <= 0)


def test_voltvar_recovers_a_monotone_curve_on_its_knots():
    rng = np.random.default_rng(2)
    s = np.array([0.4, 0.8])
    x = _random_features(rng, 600, s)
    knots = np.array([learned._quantile_knots(x.v_pu[:, i], 5) for i in range(2)])
    truth = VoltVarRule()
    truth.v_, truth.q_, truth.s_rated_mva_ = knots, np.array([[0.4, 0.3, 0.0, -0.1, -0.4], [0.2, 0.2, 0.1, -0.3, -0.3]]), s
    y = truth.predict(x)
    fitted = VoltVarRule(knots=5).fit(x, y, np.full(2, 100.0), np.ones(y.shape, dtype=bool))
    np.testing.assert_allclose(fitted.v_, knots)
    np.testing.assert_allclose(fitted.q_, truth.q_, atol=1e-6)
    assert np.all(np.diff(fitted.q_, axis=1) <= 0)


def test_1547_search_finds_the_curve_on_its_grid():
    rng = np.random.default_rng(3)
    s = np.array([1.0])
    x = _random_features(rng, 3000, s)
    points, q = np.array([0.9675, 0.99, 1.01, 1.0325]), np.array([0.3, 0.0, 0.0, -0.35])
    y = np.interp(x.v_pu[:, 0], points, q)[:, None] * s
    fitted = Ieee1547Rule().fit(x, y, np.full(1, 100.0), np.ones(y.shape, dtype=bool))
    np.testing.assert_allclose(fitted.v_[0], points, atol=1e-9)
    np.testing.assert_allclose(fitted.q_[0], q, atol=1e-9)
    # a bound below the curve's slope caps the amplitudes: |q1| / (V2 − V1) ≤ bound
    capped = Ieee1547Rule().fit(x, y, np.full(1, 5.0), np.ones(y.shape, dtype=bool))
    assert capped.v_slope()[0] <= 5.0 * (1 + 1e-12)


# ----- paper33: fitted to the AC OPF over two days ------------------------------------------
@pytest.fixture(scope="module")
def training():
    _, scenario = training_scenario("paper33", TRAIN, "20:00-05:00")
    opt = run_strategy("acopf", scenario, 0.0)
    return training_set("paper33", TRAIN, "20:00-05:00", opt.q_mvar, opt.status == "ok")


@pytest.fixture(scope="module")
def fitted(training) -> dict[tuple[str, float], LearnedParams]:
    return {(family, rho): fit_rule(family, training, rho=rho) for family in FAMILIES for rho in (0.1, 0.9)}


def _undamped(params: LearnedParams, scenario, q: np.ndarray) -> np.ndarray:
    """F(Q) = clip(f(measurements at the grid's answer to Q)) at k = 0, rows (S, n_der)."""
    net = scenario.net
    pf = solve_pf_batch(net, scenario.injections(q))
    x = learned.features(scenario, np.abs(pf.v[:, net.der_bus]))
    limit = reactive_limit(scenario, 0.0)
    return np.clip(params.rule.predict(x), -limit, limit)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_fitted_curve_obeys_its_slope_bound_and_the_loop_contracts(family, fitted, training):
    scenario = training.scenario
    every = voltage_sensitivity(scenario, np.arange(0, scenario.n_snapshots, 8))  # other operating points than the fit's
    for rho in (0.1, 0.9):
        params = fitted[(family, rho)]
        slope = params.rule.v_slope()
        assert np.all(slope <= np.array(params.slope_max_mvar_per_pu) * (1 + 1e-9))
        assert contraction_factor(every, slope) <= rho * 1.01  # X barely moves between operating points
        # the undamped iteration's map, measured: ‖F(Q) − F(Q′)‖∞ ≤ ρ‖Q − Q′‖∞ (+2 % for the non-linearity)
        rng = np.random.default_rng(7)
        rows = scenario.take(np.arange(30, scenario.n_snapshots, 24))
        limit = reactive_limit(rows, 0.0)
        q1, q2 = (rng.uniform(-1, 1, limit.shape) * limit for _ in range(2))
        ratio = np.abs(_undamped(params, rows, q1) - _undamped(params, rows, q2)).max(axis=1) / np.abs(q1 - q2).max(axis=1)
        assert ratio.max() <= rho * 1.02, (family, rho, ratio.max())
    assert fitted[(family, 0.9)].fit["contraction_factor"] <= 0.9 * (1 + 1e-9)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_learned_rules_stay_within_limits_and_settle(family, fitted, tmp_path):
    path = fitted[(family, 0.9)].write(tmp_path / f"{family}.json")
    _, test = training_scenario("paper33", TEST, "20:00-05:00")
    for k in (0.0, 0.4):
        res = run_strategy(f"{family}:params={path}", test, k)
        limit = reactive_limit(test, k)
        assert np.all(np.abs(res.q_mvar) <= limit + 1e-12)
        assert set(res.status) == {"ok"}  # settled everywhere: the slope bound makes the loop contract
        assert res.strategy == f"{family}:params={path}"


def test_the_params_file_round_trips_and_predicts_as_fitted(fitted, training, tmp_path):
    for params in fitted.values():
        path = params.write(tmp_path / "p.json")
        back = LearnedParams.parse(path.read_text(), str(path))
        assert back.text() == params.text() and back.family == params.family
        net = training.scenario.net
        x = learned.features(training.scenario, np.full(training.scenario.der_p_mw.shape, 1.01))
        np.testing.assert_array_equal(back.rule.predict(x), params.rule.predict(x))
    data = json.loads(path.read_text())
    assert data["train"]["period"] == TRAIN and data["case"] == "paper33" and len(data["ders"]) == len(net.ders)
    assert data["data_sha256"] == training.digest() and len(data["parameters"]) == len(net.ders)


def test_bad_params_files_and_labels_are_refused(fitted, tmp_path, capsys):
    params = fitted[("learned-affine", 0.9)]
    good = params.write(tmp_path / "good.json")
    data = json.loads(good.read_text())
    cases = {
        "not json": ("{", "not JSON"),
        "another format": (json.dumps({"format": "x"}), "not a learned rule's parameters"),
        "missing field": (json.dumps({k: v for k, v in data.items() if k != "rho"}), "missing or malformed"),
        "DER count": (json.dumps(data | {"parameters": data["parameters"][:-1]}), "one entry per DER"),
        "NaN": (json.dumps(data).replace('"a": ' + json.dumps(data["parameters"][0]["a"]), '"a": NaN', 1), "not finite"),
        "slope limit edited": (json.dumps(data | {"slope_max_mvar_per_pu": [1e6] * len(data["ders"])}), "is not rho / row sum"),
        "too steep": (
            json.dumps(
                data | {"row_sum_pu_per_mvar": [9e5] * len(data["ders"]), "slope_max_mvar_per_pu": [1e-6] * len(data["ders"])}
            ),
            "exceeds its slope bound",
        ),
        "Q rising with |V|": (
            json.dumps(data | {"parameters": [p | {"c": 0.01} for p in data["parameters"]]}),
            "c = 0.01 > 0: its Q would rise with its own",
        ),
    }
    for name, (text, message) in cases.items():
        bad = tmp_path / f"{name}.json"
        bad.write_text(text)
        with pytest.raises(InputError, match=message):
            configuration(f"learned-affine:params={bad}")
        assert main(["snapshot", "paper33", "--strategy", f"learned-affine:params={bad}"]) == 2
        assert message.split()[0] in capsys.readouterr().err
    # a family's parameters are not another's; a file fitted on paper33 is not case69-der's
    with pytest.raises(InputError, match="are of learned-affine, not learned-vv"):
        configuration(f"learned-vv:params={good}")
    assert main(["snapshot", "case69-der", "--strategy", f"learned-affine:params={good}"]) == 2
    assert "were fitted on paper33" in capsys.readouterr().err
    period = resolve_period(TEST, "20:00-05:00", 15)
    with pytest.raises(InputError, match="were fitted on paper33"):
        check_learned((f"learned-affine:params={good}",), ("case69-der",), period, "20:00-05:00")
    # row sums halved with the slope limits made consistent: the grid's own sensitivity refuses the steeper loop
    rows = [v * 0.25 for v in data["row_sum_pu_per_mvar"]]
    steep = dict(data, row_sum_pu_per_mvar=rows, slope_max_mvar_per_pu=[data["rho"] / v for v in rows])
    steep["parameters"] = [  # each slope at the (false) bound: 4 × what the grid allows
        p | {"c": -data["rho"] / r / d["s_mva"]} for p, r, d in zip(data["parameters"], rows, data["ders"], strict=True)
    ]
    (tmp_path / "steep.json").write_text(json.dumps(steep))
    assert main(["snapshot", "paper33", "--strategy", f"learned-affine:params={tmp_path / 'steep.json'}"]) == 2
    assert "its slopes make the closed loop no contraction" in capsys.readouterr().err
    # paper33-meshed has paper33's DER (buses, ratings) on another grid: refused, named, before any work
    assert main(["snapshot", "paper33-meshed", "--strategy", f"learned-affine:params={good}"]) == 2
    assert "paper33-meshed is another grid" in capsys.readouterr().err
    with pytest.raises(InputError, match="is another grid"):
        check_learned((f"learned-affine:params={good}",), ("paper33-meshed",), period, "20:00-05:00")
    check_learned((f"learned-affine:params={good}",), ("paper33?line-z=1.2",), period, "20:00-05:00")  # its model: allowed
    for label, message in {
        "learned-affine": "give train=START..END",
        f"learned-affine:train={TRAIN},params={good}": "one of them",
        f"learned-affine:params={good},rho=0.5": "rho are options of the fit",
        "learned-affine:train=2016-03-01": "START..END",
        "learned-affine:train=x..y,rho=1": "contraction factor",
        "learned-vv:train=x..y,knots=1": "knots must lie in 2..50",
    }.items():
        with pytest.raises(InputError, match=message):
            configuration(label)
    assert main(["snapshot", "paper33", "--strategy", f"learned-affine:train={TRAIN}"]) == 2
    assert "is fitted by opfbench run" in capsys.readouterr().err


def test_a_der_without_enough_training_samples_is_named_before_any_work(training):
    # a night: the PV units have no reactive limit at any step (the DFIG has one)
    night = "2016-03-01T22:00..2016-03-02T04:00"
    test = resolve_period(TEST, "20:00-05:00", 15)
    with pytest.raises(InputError, match=r"learned-affine: DER PV-10 \(bus 10\) has 0 training samples .* need at least 8"):
        check_learned((f"learned-affine:train={night}",), ("paper33",), test, "20:00-05:00")
    # the fit itself counts the optimum's certified steps: with none, no rule is fitted
    uncertified = learned.TrainingSet(
        training.case, training.period, training.start, training.end, training.scenario, training.q_mvar, training.ok & False
    )
    for family in FAMILIES:
        with pytest.raises(InputError, match=f"{family}: DER PV-10 \\(bus 10\\) has 0 training samples"):
            fit_rule(family, uncertified)


# ----- leakage ----------------------------------------------------------------------------
def test_training_data_hold_nothing_of_the_test_period(monkeypatch, training):
    """Perturbing every profile value from the test period on changes no training datum and
    no fitted parameter; perturbing one training step changes the data's hash."""
    from opfbench.data import profiles

    original = profiles.load_simbench_profiles()
    cut = resolve_period(TEST, "20:00-05:00", 15).index[0]

    def perturbed(after: bool):
        frame = original.copy()
        rows = frame.index >= cut if after else frame.index == cut - np.timedelta64(15, "m")
        frame.loc[rows, :] = frame.loc[rows, :] * 1.7 + 0.05
        frame.attrs = original.attrs
        return lambda: frame

    base = fit_rule("learned-affine", training).text()
    monkeypatch.setattr(profiles, "load_simbench_profiles", perturbed(after=True))
    again = training_set("paper33", TRAIN, "20:00-05:00", training.q_mvar, training.ok)
    assert again.digest() == training.digest()
    assert fit_rule("learned-affine", again).text() == base
    monkeypatch.setattr(profiles, "load_simbench_profiles", perturbed(after=False))
    changed = training_set("paper33", TRAIN, "20:00-05:00", training.q_mvar, training.ok)
    assert changed.digest() != training.digest()


def test_a_training_period_overlapping_the_test_period_is_refused(fitted, tmp_path):
    period = resolve_period("2016-03-02..2016-03-05", "20:00-05:00", 15)
    with pytest.raises(InputError, match="overlaps the test period"):
        check_learned((f"learned-affine:train={TRAIN}",), ("paper33",), period, "20:00-05:00")
    path = fitted[("learned-vv", 0.9)].write(tmp_path / "vv.json")  # fitted on TRAIN too
    with pytest.raises(InputError, match="overlaps the test period"):
        check_learned((f"learned-vv:params={path}",), ("paper33",), period, "20:00-05:00")
    adjacent = resolve_period(TEST, "20:00-05:00", 15)  # starts where the training ends: allowed
    check_learned((f"learned-affine:train={TRAIN}", f"learned-vv:params={path}"), ("paper33",), adjacent, "20:00-05:00")
    assert main(["run", "--period", "year", "--strategies", f"learned-affine:train={TRAIN}", "--out", str(tmp_path / "r")]) == 2


# ----- the voltage sensitivity and the perturbed model ---------------------------------------
def test_voltage_sensitivity_predicts_newton_raphson(paper33):
    from opfbench.scenario import Scenario

    scenario = Scenario.snapshot(paper33, 1.0, 0.6)
    x = voltage_sensitivity(scenario, np.array([0]))
    base = scenario.injections(np.zeros((1, len(paper33.ders))))[0]
    v0 = solve_pf(paper33, base).vm[paper33.der_bus]
    for j, d in enumerate(paper33.ders):
        dq = 0.002 * d.s_rated_mva
        s = base.copy()
        s[d.bus] += 1j * dq
        dv = np.abs(solve_pf(paper33, s).vm[paper33.der_bus] - v0) / dq
        np.testing.assert_allclose(dv, x[:, j], rtol=2e-3)


def test_line_z_perturbs_the_lines_only():
    spec = parse_spec("simbench:1-LV-rural3--0-sw?line-z=1.2")
    assert spec.text == "simbench:1-LV-rural3--0-sw?line-z=1.2" and spec.model.text == "simbench:1-LV-rural3--0-sw"
    base, perturbed = load_network(spec.model.text), load_network(spec.text)
    trafo = base.base_kv[base.f] != base.base_kv[base.t]
    assert trafo.sum() == 1
    np.testing.assert_array_equal(perturbed.r[trafo], base.r[trafo])
    np.testing.assert_allclose(perturbed.x[~trafo], 1.2 * base.x[~trafo], rtol=1e-15)
    np.testing.assert_allclose(perturbed.r[~trafo], 1.2 * base.r[~trafo], rtol=1e-15)
    np.testing.assert_array_equal(perturbed.b, base.b)
    assert "line-z=1.2" in load_case(spec.text).notes[-1]
    for bad in ("0", "-1", "x", "inf"):
        with pytest.raises(InputError, match="line-z"):
            parse_spec(f"paper33?line-z={bad}")


# ----- rules that keep the band -------------------------------------------------------------
def _tight_training() -> learned.TrainingSet:
    """case33bw with three large inverters at its feeder ends and its upper voltage limit
    lowered to 1.04 p.u.: at light load and high output the optimum absorbs to hold the
    band, where a rule fitted to its Q alone leaves it."""
    from functools import partial

    from opfbench.formulations.frontier import tightened
    from opfbench.formulations.opf_strategies import run_acopf
    from opfbench.scenario import Scenario

    net = load_case("case33bw?der=18:inverter:1.2,33:inverter:1.2,25:inverter:1.2").network
    net = net.with_changes(vmax=np.where(np.arange(net.n_bus) != net.slack, 1.04, net.vmax))
    rng = np.random.default_rng(3)
    load = rng.uniform(0.2, 1.0, 96)
    scenario = Scenario(net, load, rng.uniform(0.3, 1.0, (96, 1)) * net.der_rating_mw)
    opt = run_acopf(scenario, 0.0)
    ok = opt.status == "ok"
    assert ok.all()
    return learned.TrainingSet(
        "tight", "a", "", "", scenario, opt.q_mvar, ok, partial(tightened, scenario, 0.0, q_mvar=opt.q_mvar, ok=ok)
    )


def test_a_compliant_fit_refits_to_tightened_bands_until_the_rule_leaves_the_band_less(tmp_path):
    """comply (the default): the plain fit leaves the band at training steps in closed loop;
    refitted to the optimum of tightened bands, each margin's closed loop recorded, the rule
    kept leaves it at fewer steps (the first margin with none, else the fewest); the file's
    record is what the rule does in closed loop; comply=false is the plain fit."""
    training = _tight_training()
    params = fit_rule("learned-affine", training)
    tried = params.fit["comply"]
    assert tried[0]["margin_pu"] == 0.0 and tried[0]["outside_steps"] > 10
    best = min(tried, key=lambda t: (t["outside_steps"], t["train_loss_kw"]))
    assert best["outside_steps"] < tried[0]["outside_steps"] / 3 and best["margin_pu"] > 0
    assert [t["margin_pu"] for t in tried] == list(learned.MARGINS[: len(tried)])
    path = params.write(tmp_path / "rule.json")
    res = run_strategy(f"learned-affine:params={path}", training.scenario, 0.0)
    assert int((res.voltage_violation() > 1e-6).sum()) == best["outside_steps"]
    assert np.nanmean(res.losses_kw) == pytest.approx(best["train_loss_kw"], rel=1e-9)
    plain = fit_rule("learned-affine", training, comply=False)
    assert plain.fit["comply"] == [] and plain.hyper["comply"] is False
    np.testing.assert_allclose(plain.rule.coef_, fit_rule("learned-affine", replace_tightened(training)).rule.coef_)


def replace_tightened(training: learned.TrainingSet) -> learned.TrainingSet:
    """The training set without tightened optima: nothing to refit to."""
    from dataclasses import replace

    return replace(training, tightened=None)
