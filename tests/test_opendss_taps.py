"""`?taps=control` against OpenDSS's own regulators: the shipped feeder compiled and
solved by OpenDSS alone (snapshot, its control loop on, tolerance 1e-10) at several load
levels (`loadmult`; switched capacitors held where the file's snapshot settled them), and opfbench's power flow with its RegControl emulation
(`opfbench.multiphase.regulators`) at the same loads — identical tap positions, and every
node's |V| within 1e-6 p.u. (ieee13 and ieee123 by default; the other feeders with
regulators under `-m slow`)."""

from __future__ import annotations

import json

import numpy as np
import opendssdirect as dss
import pytest

from opfbench.cases.opendss_cases import opendss_copy, opendss_master
from opfbench.cli import main
from opfbench.io import load_case
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import solve_phase_flow
from tests.support.opendss_feeders import set_tap, solve

LOAD_MULTS = (0.3, 0.6, 1.0, 1.2)


def _opendss_taps(name: str, net: PhaseNetwork, mult: float):
    """OpenDSS's snapshot at loadmult `mult`, its regulators starting from the compiled
    taps: (taps per regulator of `net`, the snapshot). Switched capacitors stay where the
    file's own snapshot settled them (CapControls disabled after it), as in opfbench's
    model, which does not emulate CapControl."""
    compiled = [
        set_tap(net.elements[reg.element].name.split(".", 1)[1], reg.tap_winding, float(reg.taps[reg.start]))
        for reg in net.regulators
    ]
    with opendss_copy(name) as master:
        theirs = solve(
            master,
            "set tolerance=1e-10 maxiterations=200",
            "solve",
            "batchedit capcontrol..* enabled=no",
            *compiled,
            f"set loadmult={mult!r}",
            "set maxcontroliter=100",
        )
    taps = []
    for reg in net.regulators:
        dss.RegControls.Name(reg.name)
        dss.Transformers.Name(dss.RegControls.Transformer())
        dss.Transformers.Wdg(reg.tap_winding)
        taps.append(dss.Transformers.Tap())
    return np.array(taps), theirs


def _same_taps(name: str) -> None:
    case = load_case(f"{name}?taps=control")
    net = case.network
    assert isinstance(net, PhaseNetwork) and net.tap_control and net.regulators and case.stored is not None
    load_p, load_q, der_p, der_q = case.stored
    flow = solve_phase_flow(
        net, np.outer(LOAD_MULTS, load_p), np.outer(LOAD_MULTS, load_q), np.tile(der_p, (4, 1)), np.tile(der_q, (4, 1))
    )
    assert flow.converged.all() and flow.tap_positions is not None
    for s, mult in enumerate(LOAD_MULTS):
        ours = np.array([reg.taps[p] for reg, p in zip(net.regulators, flow.tap_positions[s], strict=True)])
        theirs, snapshot = _opendss_taps(name, net, mult)
        assert snapshot.converged
        assert ours == pytest.approx(theirs, abs=1e-12), f"{name} at loadmult {mult}: {ours} vs OpenDSS {theirs}"
        assert np.abs(flow.node_vm_pu[s] - snapshot.vm_pu).max() < 1e-6
    # the loads move the taps: light load settles lower than heavy load somewhere
    assert (flow.tap_positions[0] < flow.tap_positions[-1]).any()


@pytest.mark.parametrize("name", ["ieee13", "ieee123"])
def test_taps_control_settles_where_opendss_does(name):
    _same_taps(name)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ieee34", "ieee37", "ckt24"])
def test_taps_control_settles_where_opendss_does_on_the_other_feeders(name):
    _same_taps(name)


def test_held_taps_stay_and_pf_json_reports_the_controlled_ones(capsys):
    """taps=held (the default) keeps the settled taps at any load; taps=control moves them
    and `pf --json` says where (at loadmult 0.3 as OpenDSS does)."""
    held = load_case("ieee13").network
    assert isinstance(held, PhaseNetwork) and not held.tap_control and not held.regulators
    assert main(["pf", "ieee13?taps=control", "--load-scale", "0.3", "--der-scale", "0", "--json"]) == 0  # its placed PV idle
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["spec"] == "ieee13?taps=control"
    net = load_case("ieee13?taps=control").network
    assert isinstance(net, PhaseNetwork)
    theirs, _ = _opendss_taps("ieee13", net, 0.3)
    assert list(out["regulator_taps"].values()) == pytest.approx(theirs.tolist(), abs=1e-12)
    assert main(["pf", "ieee13", "--load-scale", "0.3", "--json"]) == 0
    assert "regulator_taps" not in json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("ieee13?taps=auto", "taps must be one of held, control"),
        ("paper33?taps=control", "taps= applies to three-phase"),
    ],
)
def test_bad_taps_option_exits_2(capsys, spec, expected):
    assert main(["pf", spec]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


def test_a_regulator_control_it_does_not_emulate_is_refused(tmp_path, capsys):
    master = tmp_path / "reversible.dss"
    master.write_text(f'redirect "{opendss_master("ieee13")}"\nedit regcontrol.reg2 reversible=yes\n')
    assert main(["pf", f"opendss:{master}?taps=control"]) == 2
    err = capsys.readouterr().err
    assert "RegControl.reg2" in err and "reversible=yes" in err and "Traceback" not in err
    assert main(["pf", f"opendss:{master}", "--json"]) == 0  # the settled taps need no emulation
    capsys.readouterr()
