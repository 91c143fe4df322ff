"""Several DER at one bus: each has a unique name, and they share what they compensate —
the bus's load and the inflow LFMA measures — in proportion to their ratings S̄, so that
together they act as one unit of their combined rating (never each the whole load)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opfbench.cli import main
from opfbench.errors import NetworkError
from opfbench.io import load_network
from opfbench.network import DER
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario

# bus 6 of case33bw is a branch node (lines to 7 and to 26), bus 18 the main feeder's end
SPLIT = "case33bw?der=6:PV:0.4,6:PV:0.8,18:PV:0.2,18:PV:0.1,30:DFIG:0.6"
JOINED = "case33bw?der=6:PV:1.2,18:PV:0.3,30:DFIG:0.6"


@pytest.mark.parametrize("strategy", ["llma", "lfma"])
@pytest.mark.parametrize("k", [0.0, 0.6])
@pytest.mark.parametrize("load_scale", [1.0, 3.0])
def test_units_at_one_bus_act_as_one_unit_of_their_combined_rating(strategy: str, k: float, load_scale: float) -> None:
    split, joined = load_network(SPLIT), load_network(JOINED)
    a = run_strategy(strategy, Scenario.snapshot(split, load_scale=load_scale, der_scale=0.8), k)
    b = run_strategy(strategy, Scenario.snapshot(joined, load_scale=load_scale, der_scale=0.8), k)
    per_bus = np.zeros((1, split.n_bus))
    np.add.at(per_bus.T, split.der_bus, a.q_mvar.T)
    assert per_bus[0, joined.der_bus] == pytest.approx(b.q_mvar[0], rel=1e-9, abs=1e-12)
    assert a.losses_kw[0] == pytest.approx(b.losses_kw[0], rel=1e-9)
    # each unit's part is its share of S̄ (both units at 6 are PV at the same output)
    assert a.q_mvar[0, 1] == pytest.approx(2 * a.q_mvar[0, 0], rel=1e-9)
    assert a.q_mvar[0, 0] != 0.0


def test_each_unit_measures_its_share_of_the_bus_load() -> None:
    net = load_network("case33bw?der=6:PV:0.4,6:DFIG:1.2,18:inverter:0.5")
    sc = Scenario.snapshot(net)
    bus_q = sc.bus_load_mva().imag[0, net.der_bus]
    np.testing.assert_allclose(net.der_share, [0.25, 0.75, 1.0])
    np.testing.assert_allclose(sc.load_q_at_der_mvar()[0], bus_q * [0.25, 0.75, 1.0])
    shared = sc.load_q_at_der_mvar()[0, :2].sum()
    assert shared == pytest.approx(bus_q[0])  # the units at bus 6 measure its load once between them


def test_der_names_are_unique_and_derived_from_kind_and_bus() -> None:
    net = load_network("case33bw?der=6:PV:0.4,6:PV:0.8,6:DFIG:0.3,18:inverter:0.1")
    assert net.der_names == ("PV-6", "PV-6-2", "DFIG-6", "inverter-18")
    named = net.with_changes(ders=(DER(5, "PV", 0.4, name="roof"), DER(5, "PV", 0.4, name="PV-6"), DER(5, "PV", 0.4)))
    assert named.der_names == ("roof", "PV-6", "PV-6-2")  # a derived name never takes a given one
    with pytest.raises(NetworkError, match="'roof' is given to more than one DER"):
        net.with_changes(ders=(DER(5, "PV", 0.4, name="roof"), DER(7, "PV", 0.4, name="roof")))


def test_pandapower_static_generators_keep_their_names(tmp_path) -> None:
    import pandapower as pp

    pnet = pp.create_empty_network()
    buses = [pp.create_bus(pnet, vn_kv=20.0) for _ in range(3)]
    pp.create_ext_grid(pnet, buses[0])
    for f, t in ((0, 1), (1, 2)):
        pp.create_line_from_parameters(pnet, buses[f], buses[t], 1.0, 0.2, 0.4, 10.0, 0.4)
    pp.create_load(pnet, buses[2], p_mw=0.5, q_mvar=0.2)
    for name in ("roof A", "roof B", "twin", "twin", None):
        pp.create_sgen(pnet, buses[2], p_mw=0.1, name=name)
    path = tmp_path / "named.json"
    pp.to_json(pnet, str(path))
    # the repeated name names no unit alone: those units get derived names
    assert load_network(str(path)).der_names == ("roof A", "roof B", "inverter-2", "inverter-2-2", "inverter-2-3")


def test_snapshot_json_has_a_setpoint_for_every_der(capsys: pytest.CaptureFixture) -> None:
    spec = "case33bw?der=6:PV:0.4,6:PV:0.8,18:PV:0.2"
    assert main(["snapshot", spec, "--strategy", "llma", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert list(got["q_mvar"]) == ["PV-6", "PV-6-2", "PV-18"]
    assert got["der_bus"] == {"PV-6": 6, "PV-6-2": 6, "PV-18": 18}
    assert got["q_mvar"]["PV-6-2"] == pytest.approx(2 * got["q_mvar"]["PV-6"], rel=1e-9)
