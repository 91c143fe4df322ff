"""pandapower net → Network on small hand-built nets: every element the converter maps,
against pandapower's `runpp` (|V| within 1e-6 p.u., losses within 1e-3 kW); everything it
refuses, with the table and index named; `.json` files through `load_case`."""

from __future__ import annotations

import copy
import json
import re
import warnings

import numpy as np
import pandapower as pp
import pandas as pd
import pytest

from opfbench.cli import main
from opfbench.errors import CaseFormatError
from opfbench.io import load_case
from opfbench.io.pandapower import from_pandapower
from opfbench.powerflow import solve_pf
from opfbench.scenario import Scenario


def _radial() -> pp.pandapowerNet:
    """Lines with charging, a fused and an impedance bus-bus switch, an open line end, two
    parallel transformers, a tapped transformer (LV side, phase shift), an island, several
    loads per bus, sgens of several kinds, a shunt."""
    net = pp.create_empty_network(sn_mva=1.0)
    b = {k: pp.create_bus(net, 20.0, index=k, min_vm_pu=0.95, max_vm_pu=1.05) for k in (10, 20, 21, 22, 23, 50)}
    b |= {k: pp.create_bus(net, 0.4, index=k) for k in (30, 31)}
    pp.create_ext_grid(net, b[10], vm_pu=1.02, s_sc_max_mva=300.0, rx_max=0.2)
    cable = dict(r_ohm_per_km=0.206, x_ohm_per_km=0.08, c_nf_per_km=830.0, max_i_ka=0.3)
    pp.create_line_from_parameters(net, b[10], b[20], 2.0, g_us_per_km=1.0, **cable)
    pp.create_switch(net, b[20], b[21], et="b", closed=True)
    pp.create_switch(net, b[20], b[23], et="b", closed=True, z_ohm=0.5)
    pp.create_line_from_parameters(net, b[21], b[22], 1.5, **cable)
    l_open = pp.create_line_from_parameters(net, b[20], b[22], 3.0, **cable)
    pp.create_switch(net, b[22], l_open, et="l", closed=False)  # the loop's open point
    l_island = pp.create_line_from_parameters(net, b[22], b[50], 1.0, **cable)
    pp.create_switch(net, b[22], l_island, et="l", closed=False)  # bus 50 left without supply
    trafo = dict(sn_mva=0.4, vn_hv_kv=20.0, vn_lv_kv=0.4, vk_percent=6.0, vkr_percent=1.2, pfe_kw=1.2, i0_percent=0.3)
    pp.create_transformer_from_parameters(
        net,
        b[22],
        b[30],
        shift_degree=150.0,
        tap_side="lv",
        tap_neutral=0,
        tap_pos=2,
        tap_step_percent=2.5,
        tap_changer_type="Ratio",
        **trafo,
    )
    for _ in range(2):
        pp.create_transformer_from_parameters(net, b[20], b[31], **trafo)
    pp.create_load(net, b[30], p_mw=0.05, q_mvar=0.02)
    pp.create_load(net, b[30], p_mw=0.03, q_mvar=-0.01)
    pp.create_load(net, b[31], p_mw=0.12, q_mvar=0.04, scaling=0.8)
    pp.create_load(net, b[23], p_mw=0.2, q_mvar=0.05)
    pp.create_load(net, b[50], p_mw=0.1, q_mvar=0.0)
    pp.create_sgen(net, b[30], p_mw=0.04, type="PV")
    pp.create_sgen(net, b[31], p_mw=0.06, q_mvar=0.01, sn_mva=0.1, type="WP")
    pp.create_sgen(net, b[21], p_mw=0.3, max_p_mw=0.5, type="Biomass")
    pp.create_shunt(net, b[31], q_mvar=0.01, p_mw=0.001)
    return net


def _meshed() -> pp.pandapowerNet:
    """A loop through an ideal phase shifter and a tapped transformer with a step angle."""
    net = pp.create_empty_network()
    b = [pp.create_bus(net, 110.0) for _ in range(2)] + [pp.create_bus(net, 20.0) for _ in range(3)]
    pp.create_ext_grid(net, b[0], vm_pu=1.0)
    line = dict(r_ohm_per_km=0.12, x_ohm_per_km=0.39, c_nf_per_km=9.5, max_i_ka=0.6)
    pp.create_line_from_parameters(net, b[0], b[1], 10.0, **line)
    common = dict(sn_mva=40.0, vn_hv_kv=110.0, vn_lv_kv=20.0, vk_percent=12.0, vkr_percent=0.4, pfe_kw=20.0, i0_percent=0.05)
    pp.create_transformer_from_parameters(net, b[0], b[2], **common)
    pp.create_transformer_from_parameters(
        net, b[1], b[3], tap_side="hv", tap_neutral=0, tap_pos=3, tap_step_percent=1.0, tap_step_degree=5.0,
        tap_changer_type="Ratio", **common,
    )  # fmt: skip
    pp.create_transformer_from_parameters(
        net, b[1], b[4], tap_side="hv", tap_neutral=0, tap_pos=-2, tap_step_degree=2.0, tap_changer_type="Ideal", **common
    )
    cable = dict(r_ohm_per_km=0.16, x_ohm_per_km=0.12, c_nf_per_km=260.0, max_i_ka=0.4)
    for a, c in ((2, 3), (3, 4), (4, 2)):
        pp.create_line_from_parameters(net, b[a], b[c], 4.0, **cable)
    for k in (2, 3, 4):
        pp.create_load(net, b[k], p_mw=6.0, q_mvar=2.0)
    pp.create_sgen(net, b[3], p_mw=4.0, type="PV")
    return net


def _compare(pnet) -> tuple[float, float]:
    """(largest |ΔV| p.u., |Δ losses| kW) of our power flow at the stored values vs runpp."""
    conv = from_pandapower(pnet, "test")
    net = conv.network
    sc = Scenario.from_series(net, conv.stored_load_p_mw[None], conv.stored_load_q_mvar[None], conv.stored_der_p_mw[None])
    ours = solve_pf(net, sc.injections(conv.stored_der_q_mvar[None])[0])
    assert ours.converged
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.runpp(pnet, tolerance_mva=1e-11, numba=False)
    vm = pnet.res_bus.vm_pu.dropna()
    dv = max(abs(ours.vm[conv.bus_of[int(i)]] - v) for i, v in vm.items())
    switches = (pnet.res_switch.p_from_mw + pnet.res_switch.p_to_mw).sum()  # impedance switches (z_ohm > 0)
    losses = (pnet.res_line.pl_mw.sum() + pnet.res_trafo.pl_mw.sum() + switches) * 1e3
    return float(dv), abs(float(ours.losses_kw) - losses)


@pytest.mark.parametrize("build", [_radial, _meshed])
def test_agrees_with_runpp(build):
    dv, dloss = _compare(build())
    assert dv < 1e-6 and dloss < 1e-3


def test_radial_structure_and_notes():
    conv = from_pandapower(_radial(), "radial")
    net = conv.network
    notes = " | ".join(conv.notes)
    assert "parallel branch" in notes and "auxiliary bus" in notes and "not connected to the external grid" in notes
    assert "phase shift of 1 transformer" in notes and not net.meshed and not net.shift.any()
    assert 50 not in net.bus_ids and 21 not in net.bus_ids  # 50 islanded, 21 fused into 20
    assert conv.bus_of[21] == conv.bus_of[20] and net.v_slack == 1.02
    assert np.isclose(net.tap, 1 / 1.05).any()  # +2 steps of 2.5 % on the LV side
    assert [d.primary_energy for d in net.ders] == ["solar", "wind", "biomass"]
    assert np.allclose(net.der_rating_mw, [0.04, 0.06, 0.5]) and np.allclose(net.der_s_mva, [0.04 / 0.9, 0.1, 0.5 / 0.9])
    assert np.allclose(conv.stored_der_p_mw, [0.04, 0.06, 0.3]) and conv.stored_der_q_mvar[1] == 0.01
    assert net.n_load == 4 and np.isclose(conv.stored_load_p_mw[2], 0.096)  # scaling applied; the island's load dropped
    assert conv.short_circuit == (300.0, 0.2)
    assert net.g.any() and (net.vmin[net.bus_ids < 30] == 0.95).all()


def test_meshed_keeps_loop_phase_shifts():
    net = from_pandapower(_meshed(), "meshed").network
    assert net.meshed and (net.shift != 0).sum() == 2


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda n: pp.create_gen(n, 3, p_mw=1.0, vm_pu=1.0), "table 'gen' index 0: voltage-controlled generators"),
        (lambda n: pp.create_storage(n, 3, p_mw=1.0, max_e_mwh=2.0), "table 'storage' index 0"),
        (lambda n: pp.create_impedance(n, 2, 3, 0.01, 0.01, 10.0), "table 'impedance' index 0"),
        (lambda n: pp.create_dcline(n, 2, 3, 1.0, 0.0, 0.0, 1.0, 1.0), "table 'dcline' index 0: DC lines"),
        (
            lambda n: pp.create_transformer3w(n, 0, 2, 3, "63/25/38 MVA 110/20/10 kV"),
            "table 'trafo3w' index 0: three-winding",
        ),
        (lambda n: pp.create_ext_grid(n, 1, vm_pu=1.0), "exactly one in-service external grid .* found 2"),
        (lambda n: n.ext_grid.drop(n.ext_grid.index, inplace=True), "found 0"),
        (lambda n: n.load.__setitem__("const_z_p_percent", 50.0), "table 'load' index 0: const_z_p_percent"),
        (lambda n: n.sgen.__setitem__("p_mw", 0.0), "table 'sgen' index 0: no positive rating"),
    ],
)
def test_unmappable_elements_are_refused(change, message):
    net = _meshed()
    change(net)
    with pytest.raises(CaseFormatError, match=message):
        from_pandapower(net, "meshed")


@pytest.fixture(scope="module")
def meshed() -> pp.pandapowerNet:
    """`_meshed()` built once; each test changes its own deep copy."""
    return _meshed()


def _cell(table: str, column: str, value: object, row: int = 0):
    def change(n):
        n[table][column] = n[table].get(column, pd.Series(np.nan, index=n[table].index)).astype(object)
        n[table].loc[n[table].index[row], column] = value

    return change


@pytest.mark.parametrize(
    "change, message",
    [  # a value pandapower's power flow needs is never replaced by a default
        (_cell("load", "p_mw", np.nan), "table 'load' index 0: p_mw is empty; pandapower's power flow needs a number"),
        (_cell("load", "q_mvar", "lots", 1), "table 'load' index 1: q_mvar is 'lots', not a finite number"),
        (_cell("load", "scaling", np.inf), "table 'load' index 0: scaling is inf, not a finite number"),
        (_cell("load", "p_mw", True), "table 'load' index 0: p_mw is True, not a finite number"),
        (_cell("load", "in_service", "no"), "table 'load' index 0: in_service is 'no', not true or false"),
        (_cell("load", "bus", 99), "table 'load' index 0: bus 99 is not a bus of table 'bus'"),
        (_cell("line", "r_ohm_per_km", np.nan), "table 'line' index 0: r_ohm_per_km is empty"),
        (_cell("line", "length_km", -1.0), "table 'line' index 0: length_km is -1; it must be > 0"),
        (_cell("line", "parallel", 0), "table 'line' index 0: parallel is 0; it must be > 0"),
        (_cell("line", "to_bus", 7, 1), "table 'line' index 1: to_bus 7 is not a bus of table 'bus'"),
        (_cell("trafo", "vkr_percent", np.nan), "table 'trafo' index 0: vkr_percent is empty"),
        (_cell("trafo", "sn_mva", 0.0), "table 'trafo' index 0: sn_mva is 0; it must be > 0"),
        (_cell("trafo", "tap_pos", "up", 1), "table 'trafo' index 1: tap_pos is 'up', not a finite number"),
        (_cell("sgen", "p_mw", np.nan), "table 'sgen' index 0: p_mw is empty"),
        (_cell("bus", "vn_kv", 0.0, 2), "table 'bus' index 2: vn_kv is 0; it must be > 0"),
        (_cell("bus", "max_vm_pu", "high", 2), "table 'bus' index 2: max_vm_pu is 'high', not a finite number"),
        (_cell("ext_grid", "vm_pu", np.nan), "table 'ext_grid' index 0: vm_pu is empty"),
        (lambda n: n.load.drop(columns="q_mvar", inplace=True), "table 'load' has no column 'q_mvar'"),
        (lambda n: n.__setitem__("sn_mva", 0.0), "the net's sn_mva is 0.0; it must be a positive number"),
    ],
)
def test_values_pandapower_needs_are_refused_not_defaulted(meshed, change, message):
    net = copy.deepcopy(meshed)
    change(net)
    with pytest.raises(CaseFormatError, match=re.escape(f"meshed: {message}")):
        from_pandapower(net, "meshed")


@pytest.mark.parametrize("twin", [False, True])
def test_a_line_without_impedance_is_refused_naming_it(meshed, twin):
    net = copy.deepcopy(meshed)
    row = net.line.index[0]
    if twin:  # a zero-impedance copy beside a real line: merged as parallel lines, it would divide by zero
        row = pp.create_line_from_parameters(net, net.line.from_bus.iloc[0], net.line.to_bus.iloc[0], 1.0, 0.0, 0.0, 0.0, 1.0)
    else:
        net.line.loc[row, ["r_ohm_per_km", "x_ohm_per_km"]] = 0.0
    with pytest.raises(CaseFormatError, match=f"meshed: table 'line' index {row}: r_ohm_per_km = x_ohm_per_km = 0"):
        from_pandapower(net, "meshed")


def test_optional_values_left_empty_keep_pandapowers_defaults(meshed):
    net = copy.deepcopy(meshed)
    for table, column in (("sgen", "max_p_mw"), ("sgen", "sn_mva"), ("bus", "min_vm_pu"), ("trafo", "tap_step_percent")):
        net[table][column] = np.nan
    converted = from_pandapower(net, "meshed").network
    assert converted.der_rating_mw[0] == 4.0 and converted.vmin.min() == 0.9


def test_text_in_a_number_column_of_a_json_file_exit_2(tmp_path, capsys, meshed):
    path = tmp_path / "grid.json"
    pp.to_json(meshed, str(path))
    outer = json.loads(path.read_text())
    load = json.loads(outer["_object"]["load"]["_object"])
    load["data"][0][load["columns"].index("p_mw")] = "lots"  # pandapower reads it back as text
    outer["_object"]["load"]["_object"] = json.dumps(load)
    path.write_text(json.dumps(outer))
    assert main(["pf", str(path)]) == 2
    assert capsys.readouterr().err == f"opfbench pf: error: {path}: table 'load' index 0: p_mw is 'lots', not a finite number\n"


def test_json_file_through_load_case(tmp_path):
    path = tmp_path / "grid.json"
    pp.to_json(_radial(), str(path))
    case = load_case(str(path))
    assert case.network.name == "grid" and len(case.network.ders) == 3 and case.series is None
    assert case.stored is not None and case.short_circuit == (300.0, 0.2)
    for arr in (*case.stored, case.load_index, case.der_index):  # the cached case is shared: read-only
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 0
    assert load_case(f"{path}?der-pf=0.95").network.der_s_mva[0] == pytest.approx(0.04 / 0.95)


@pytest.mark.parametrize(
    "text, message",
    [
        (json.dumps({"a": 1}), "not a pandapower net"),
        ("{not json", "not a pandapower net"),
    ],
)
def test_json_that_is_not_a_pandapower_net_exit_2(tmp_path, capsys, text, message):
    path = tmp_path / "other.json"
    path.write_text(text)
    assert main(["pf", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and str(path) in err and err.count("\n") == 1
