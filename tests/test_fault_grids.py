"""The fault study on a SimBench grid: its upstream source from the case's short-circuit
data (SimBench gives none: the CIGRE benchmark values), a step of its own profiles as the
operating point."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opfbench.cli import main
from opfbench.dynamics.params import ModelParams
from opfbench.dynamics.point import case_source, operating_point
from opfbench.errors import InputError
from opfbench.io import load_case

SPEC = "simbench:1-LV-rural1--0-sw"


def test_source_from_the_short_circuit_data():
    case = load_case(SPEC)
    assert case.short_circuit == (100.0, 1.0)  # fed from 20 kV: CIGRE's LV benchmark value
    src = case_source(case, ModelParams()).source
    assert abs(src.z_pu) == pytest.approx(case.network.base_mva / 100.0) and src.resistance_pu == pytest.approx(src.impedance_pu)
    mv = load_case("simbench:1-MV-urban--0-sw")
    assert mv.short_circuit == (5000.0, 0.1)
    assert case_source(load_case("paper33"), ModelParams()) == ModelParams()  # no data: the reference j0.2


def test_a_profile_step_as_operating_point():
    case = load_case(SPEC)
    sc = operating_point(case.network, time="2016-06-21T12:00", case=case).scenario
    i = int(np.flatnonzero(case.series.index == "2016-06-21T12:00+02:00")[0])
    p, _, der = case.series.rows(case.series.index[i : i + 2])
    assert np.array_equal(sc.load_p_mw[0], p[0]) and np.array_equal(sc.der_p_mw[0], der[0])
    assert np.array_equal(sc.der_p_forecast_mw[0], der[1])  # the oracle: the next quarter hour
    with pytest.raises(InputError, match="occurs twice"):
        operating_point(case.network, time="2016-10-30T02:30", case=case)


def test_fault_cli_on_a_simbench_grid(tmp_path, capsys):
    out = tmp_path / "fault"
    argv = ["fault", SPEC, "--fault-bus", "6", "--strategies", "no-action", "lfma", "--k", "0", "--time", "2016-06-21T12:00"]
    assert main([*argv, "--json", "--out", str(out)]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 2 and {r["status"] for r in records} == {"recovered"}
    source = json.loads((out / "manifest.json").read_text())["variants"]["reference"]["source"]
    z = load_case(SPEC).network.base_mva / 100.0  # S″k 100 MVA, R/X 1
    assert source["impedance_pu"] == pytest.approx(z / np.sqrt(2)) and source["resistance_pu"] == pytest.approx(z / np.sqrt(2))
