"""SimBench grids through `load_case("simbench:CODE")`: the converter against pandapower's
`runpp` (every bus |V| within 1e-6 p.u., losses within 1e-3 kW) at the stored values and
at three profile steps, and every SimBench pitfall the converter handles.

The field suite's ten grids run under `pytest -m slow`; two of them (a small LV grid and
1-MV-urban, whose transformers sit off-neutral) in the default suite."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.errors import DataError, InputError
from opfbench.io import load_case
from opfbench.io.simbench import SUITE, check_code
from opfbench.powerflow import solve_pf
from opfbench.scenario import Scenario
from opfbench.study.periods import local_time
from tests.support.simbench_oracle import STEPS, runpp_at

FAST = ("1-LV-rural1--0-sw", "1-MV-urban--0-sw")
V_TOL, LOSS_TOL_KW = 1e-6, 1e-3


def _ours(code: str, step: str | None):
    case = load_case(f"simbench:{code}")
    net = case.network
    if step is None:
        scenario, q = Scenario.of_case(case), case.stored[3]
    else:
        day, clock = STEPS[step].split(" ")
        d, m, y = day.split(".")
        when = local_time(f"{y}-{m}-{d}T{clock}")
        scenario, q = Scenario.of_case(case, pd.DatetimeIndex([when])), np.zeros(len(net.ders))
    res = solve_pf(net, scenario.injections(q[None, :])[0])
    assert res.converged
    return net, res


@pytest.mark.parametrize("step", [None, *STEPS])
@pytest.mark.parametrize("code", [pytest.param(c, marks=() if c in FAST else pytest.mark.slow) for c in SUITE])
def test_converter_agrees_with_runpp(code, step):
    net, ours = _ours(code, step)
    pnet, pp_losses = runpp_at(code, step)
    real = net.bus_ids <= pnet.bus.index.max()  # the auxiliary buses at open line ends have no pandapower row
    vm_pp = pnet.res_bus.vm_pu.loc[net.bus_ids[real]].to_numpy()
    assert np.abs(ours.vm[real] - vm_pp).max() < V_TOL
    assert abs(float(ours.losses_kw) - pp_losses) < LOSS_TOL_KW
    fused = pnet.res_bus.vm_pu.dropna()  # every in-service pandapower bus, fused ones included
    assert np.abs(fused.to_numpy() - ours.vm[[_index(net, pnet, b) for b in fused.index]]).max() < V_TOL


def _index(net, pnet, pp_bus: int) -> int:
    """Our bus of pandapower bus `pp_bus`: itself, or the one a chain of closed bus-bus
    switches fused it into (found by walking the switches, not by the converter's map)."""
    ours = set(net.bus_ids.tolist())
    sw = pnet.switch[(pnet.switch.et == "b") & pnet.switch.closed]
    seen, todo = {pp_bus}, [pp_bus]
    while todo:
        b = todo.pop()
        if b in ours:
            return net.index_of(b)
        for other in set(sw.element[sw.bus == b]) | set(sw.bus[sw.element == b]):
            if other not in seen:
                seen.add(other)
                todo.append(int(other))
    raise AssertionError(f"pandapower bus {pp_bus} has no bus in the network")


def test_taps_are_applied_as_simbench_intends():
    """simbench 1.6.3 leaves tap_changer_type empty: pandapower 3.x then ignores 1-MV-urban's
    tap −1 and its voltages differ; the case applies the taps and says so."""
    case = load_case("simbench:1-MV-urban--0-sw")
    assert any("taps applied" in n and "tap -1" in n for n in case.notes)
    assert np.isclose(case.network.tap, 1 - 0.015).sum() == 2  # tap −1 of 1.5 % on the HV side
    _, ours = _ours("1-MV-urban--0-sw", None)
    ignored, _ = runpp_at("1-MV-urban--0-sw", None, fix_taps=False)
    net = case.network
    real = net.bus_ids <= ignored.bus.index.max()
    assert np.abs(ours.vm[real] - ignored.res_bus.vm_pu.loc[net.bus_ids[real]].to_numpy()).max() > 1e-2


def test_stored_values_slack_and_structure():
    lv, mv = (load_case(f"simbench:{code}") for code in FAST)
    for case in (lv, mv):
        net = case.network
        assert net.v_slack == 1.025  # the external grid's vm_pu, not 1.0
        load_p, _, der_p, _ = case.stored
        assert np.array_equal(der_p, net.der_rating_mw)  # the stored sgen output is its rating
        assert np.allclose(np.bincount(net.load_bus, load_p, net.n_bus), net.load_p_mw)
        assert np.allclose(net.der_s_mva, net.der_rating_mw / 0.9)  # S̄ = P̄/0.90 (sn_mva = p_mw)
    assert mv.network.n_load > np.unique(mv.network.load_bus).size  # several loads share a bus
    assert not np.array_equal(lv.network.bus_ids, np.arange(lv.network.n_bus))  # bus indices are not contiguous
    assert all(d.kind == "inverter" and d.primary_energy == "solar" for d in lv.network.ders)
    assert {d.primary_energy for d in mv.network.ders} == {"solar", "hydro"}  # lv_RES and Hydro_MV


def test_local_time_with_daylight_saving():
    """The profiles' time column is German local time: 27 March skips 02:00-02:45, 30
    October repeats it; the index is strictly increasing at 15 min in absolute time."""
    index = load_case("simbench:1-LV-rural1--0-sw").series.index
    assert len(index) == 35136 and index.is_monotonic_increasing and not index.has_duplicates
    assert (np.diff(index.asi8) == 15 * 60 * 10**9).all()
    local = index.tz_convert("Europe/Berlin")
    march = local[local.strftime("%Y-%m-%d") == "2016-03-27"]
    assert "02:00" not in set(march.strftime("%H:%M")) and len(march) == 92
    october = local[local.strftime("%Y-%m-%d") == "2016-10-30"]
    assert list(october.strftime("%H:%M")).count("02:15") == 2 and len(october) == 100


@pytest.mark.slow
def test_negative_wind_profile_values_are_kept():
    """Wind profiles dip to −1e-5 p.u. (standby consumption): the DER's P is negative,
    unclipped, as profile × rating, and its capability stays defined."""
    case = load_case("simbench:1-MV-rural--0-sw")
    series = case.series
    der_p = series.der_pu[:, series.der_col] * series.der_base_mw
    assert der_p.min() < 0
    s, d = np.unravel_index(np.argmin(der_p), der_p.shape)
    sc = Scenario.of_case(case, series.index[s : s + 1])
    assert sc.der_p_mw[0, d] == der_p[s, d] < 0
    assert case.network.ders[d].primary_energy == "wind"
    assert (sc.qmax_mvar()[0, d] >= 0) and np.isfinite(sc.qmax_mvar()).all()


def test_negative_load_q_is_kept():
    """Capacitive load Q (negative) reaches the scenario unclipped."""
    series = load_case("simbench:1-MV-urban--0-sw").series
    case = load_case("simbench:1-MV-urban--0-sw")
    load_q = series.load_q_pu[:, series.load_q_col] * series.load_q_base_mvar
    assert load_q.min() < 0
    row = int(np.argmin(load_q.min(axis=1)))
    assert Scenario.of_case(case, series.index[row : row + 1]).load_q_mvar.min() == load_q[row].min()


def test_cached_per_process():
    assert load_case("simbench:1-LV-rural1--0-sw") is load_case("simbench:1-LV-rural1--0-sw")


@pytest.mark.parametrize(
    "code, message",
    [
        ("1-MV-rurl--0-sw", "closest: 1-MV-rural--0-sw"),
        ("1-HV-mixed--0-sw", "HV and EHV grids are meshed transmission grids with voltage-controlled generators"),
        ("1-EHV-mixed--0-sw", "is a EHV grid"),
    ],
)
def test_bad_codes(code, message):
    with pytest.raises(InputError, match=message):
        check_code(code)


def test_pf_command_as_stored_and_at_a_profile_step(capsys):
    code = "1-LV-rural1--0-sw"
    assert main(["pf", f"simbench:{code}", "--json"]) == 0
    stored = json.loads(capsys.readouterr().out)
    assert stored["operating_point"] == "stored" and stored["load_scale"] is None and stored["der_scale"] is None
    assert stored["losses_kw"] == pytest.approx(runpp_at(code, None)[1], abs=LOSS_TOL_KW)
    assert main(["pf", f"simbench:{code}", "--time", "2016-11-08T12:00", "--json"]) == 0
    step = json.loads(capsys.readouterr().out)
    assert step["operating_point"] == "profile" and step["time"] == "2016-11-08T12:00:00+01:00"
    assert step["losses_kw"] == pytest.approx(runpp_at(code, "november")[1], abs=LOSS_TOL_KW)
    assert main(["pf", f"simbench:{code}", "--load-scale", "0.5", "--json"]) == 0
    scaled = json.loads(capsys.readouterr().out)
    assert scaled["operating_point"] == "scaled" and scaled["load_mw"] == pytest.approx(stored["load_mw"] / 2)
    assert scaled["der_mw"] == pytest.approx(0.8 * stored["der_mw"])  # der-scale's default, of the ratings


@pytest.mark.parametrize(
    "argv, message",
    [
        (["pf", "simbench:1-LV-rural9--0-sw"], "unknown SimBench code '1-LV-rural9--0-sw'; closest:"),
        (["pf", "simbench:1-HV-urban--0-sw"], "voltage-controlled generators"),
        (["pf", "simbench:1-LV-rural1--0-sw", "--time", "2016-03-27T02:30"], "does not exist"),
        (["pf", "simbench:1-LV-rural1--0-sw", "--time", "2016-06-01T12:00", "--der-scale", "0.5"], "drop --load-scale"),
        (["pf", "paper33", "--time", "2016-06-01T12:00"], "needs a case with its own time series"),
    ],
)
def test_bad_input_is_one_message_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_a_profile_with_nan_is_refused():
    from opfbench.io.pandapower import from_pandapower
    from opfbench.io.simbench import _series
    from tests.support.simbench_oracle import fresh_net

    net = fresh_net("1-LV-rural1--0-sw")
    column = f"{net.load.profile.iloc[0]}_pload"
    net.profiles["load"].loc[100, column] = np.nan
    conv = from_pandapower(net, "nan")
    with pytest.raises(
        DataError, match=rf"profile '{column}' \('load'\) has 1 missing or non-numeric value\(s\), first at 2016-01-02 01:00"
    ):
        _series(net, conv, "1-LV-rural1--0-sw")
