"""Every local rule per DER on the three-phase feeders (the one rule engine, `strategies.grids`),
and the Volt-VAR closed loop against OpenDSS's InvControl VOLTVAR on the same feeder
(`tests/support/opendss_feeders.volt_var`: the shipped file compiled by OpenDSS alone, one
PVSystem per DER): Q per DER within 1e-6 p.u. of its S̄, every node's |V| within 1e-7 p.u.
— on `eulv` (its 28 single-phase PV), `ieee123` with single-phase units, and `ieee13` with
three-phase units (their measured voltage the average of their phases)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opfbench.cases.opendss_cases import opendss_copy, opendss_master
from opfbench.cli import main
from opfbench.io import load_case
from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.registry.catalog import run_strategy, specs
from opfbench.scenario import Scenario
from opfbench.strategies.limits import reactive_limit
from opfbench.strategies.standards import VOLT_VAR
from tests.support.opendss_feeders import volt_var

Q_TOL_PU, V_TOL_PU = 1e-6, 1e-7
TIGHT_VOLT_VAR = "volt-var:tol_q_mvar=1e-10"  # the default 1e-7 MVAr is 2e-5 p.u. of a 4 kVA house's unit
IEEE123_DER = "?der=" + ",".join(
    f"{bus}:inverter:{mw}" for bus, mw in (("49.1", 0.05), ("65.2", 0.08), ("76.3", 0.1), ("114.1", 0.03), ("300", 0.2))
)
IEEE13_DER = "?der=675:inverter:0.5,671:inverter:0.4,611.3:inverter:0.05,652.1:inverter:0.05"


def _units(net: PhaseNetwork, scenario: Scenario) -> list[tuple[str, float, float, float, float]]:
    """Our DER as OpenDSS PVSystems: bus1 with its nodes, kV, kVA, Pmpp, P."""
    out = []
    db = net.der_branches
    for d, der in enumerate(net.ders):
        mine = np.flatnonzero(db.owner == d)
        phases = [int(net.node_phase[a]) for a in db.a[mine]]
        neutral = int(db.b[mine[0]])
        end = 0 if neutral == GROUND else int(net.node_phase[neutral])
        bus1 = ".".join([net.bus_names[der.bus], *map(str, phases), str(end)])
        kv = net.bus_kv_ln[der.bus] * (np.sqrt(3.0) if len(phases) > 1 else 1.0)
        out.append((bus1, float(kv), der.s_rated_mva * 1e3, der.rating_mw * 1e3, float(scenario.der_p_mw[0, d]) * 1e3))
    return out


@pytest.mark.parametrize(
    "spec, load_scale, der_scale, k",
    [
        ("eulv", 1.0, 0.8, 0.0),
        ("eulv", 1.4, 0.3, 0.4),
        (f"ieee123{IEEE123_DER}", 0.6, 0.9, 0.0),
        (f"ieee13{IEEE13_DER}", 0.5, 0.9, 0.0),
    ],
)
def test_volt_var_closed_loop_equals_opendss_invcontrol(spec, load_scale, der_scale, k):
    case = load_case(spec)
    net = case.network
    assert isinstance(net, PhaseNetwork)
    scenario = Scenario.snapshot(net, load_scale, der_scale)
    ours = run_strategy(TIGHT_VOLT_VAR, scenario, k)
    assert ours.status[0] == "ok"
    limit = reactive_limit(scenario, k)[0]
    v, q = VOLT_VAR["b"]
    curves = [(np.array(q) * s / lim, float(lim) * 1e3) for s, lim in zip(net.der_s_mva, limit, strict=True)]
    with opendss_copy(spec.split("?")[0]) as master:
        theirs = volt_var(master, load_scale, _units(net, scenario), v, curves)
    assert theirs.converged
    np.testing.assert_allclose(theirs.p_mw, scenario.der_p_mw[0], atol=1e-9)
    dq = np.abs(theirs.q_mvar - ours.q_mvar[0]) / net.der_s_mva
    assert dq.max() < Q_TOL_PU, f"{spec}: |ΔQ| {dq.max():.2e} p.u. of S̄ at {net.der_names[int(dq.argmax())]}"
    assert np.abs(ours.q_mvar[0]).max() > 0.05 * net.der_s_mva.max()  # the rule acts
    flow = scenario.flow(ours.q_mvar)
    assert theirs.node_names == list(net.node_names)
    dv = np.abs(flow.node_vm_pu[0] - theirs.vm_pu)
    assert dv.max() < V_TOL_PU, f"{spec}: |ΔV| {dv.max():.2e} p.u. at {net.node_names[int(dv.argmax())]}"


def test_every_local_rule_runs_per_der_on_eulv():
    """Every registered local rule on eulv's 28 single-phase PV: a result per DER, each
    within its limit, voltages and VUF reported; LLMA's own load is its house's phase load."""
    net = load_case("eulv").network
    assert isinstance(net, PhaseNetwork) and len(net.ders) == 28
    assert net.der_names[:2] == ("34.1", "70.1")  # LOAD1 and LOAD3's houses and phases
    scenario = Scenario.snapshot(net, 1.0, 0.8)
    limit = reactive_limit(scenario, 0.0)
    local = [s.name for s in specs() if s.kind == "local" and not s.learned]
    assert {"no-action", "llma", "lfma", "volt-var"} <= set(local)
    for name in local:
        res = run_strategy(name, scenario, 0.0)
        assert res.status[0] == "ok", name
        assert (np.abs(res.q_mvar[0]) <= limit[0] + 1e-12).all(), name
        assert 0.9 < res.vmin[0] <= res.vmax[0] < 1.1 and 0 < res.extra["max_vuf_pct"][0] < 2, name
    llma = run_strategy("llma", scenario, 0.0)
    house = np.tan(np.arccos(0.95)) * 1e-3  # each house: 1 kW at power factor 0.95 (the file's loads)
    np.testing.assert_allclose(llma.q_mvar[0], house, rtol=1e-9)


def test_load_on_a_der_phase_is_shared_by_rating():
    """Units on one house's phase share its load by their S̄ per phase — a three-phase
    unit at the bus takes its share of each of its phases."""
    net = load_case("eulv?der=34.1:inverter:0.003,34.1:inverter:0.001,34:inverter:0.01").network
    assert isinstance(net, PhaseNetwork)
    load = Scenario.snapshot(net, 1.0, 0.5).load_q_at_der_mvar()[0]
    house = np.tan(np.arccos(0.95)) * 1e-3  # LOAD1 on 34.1, the bus's only load
    per_phase = np.array([0.003, 0.001, 0.01 / 3]) / 0.9  # S̄ per phase of each unit on 34.1
    np.testing.assert_allclose(load, house * per_phase / per_phase.sum(), rtol=1e-12)
    assert net.der_names == ("34.1", "34.1-2", "34.1.2.3")


def test_snapshot_json_keys_q_by_der_name(capsys):
    assert main(["snapshot", "eulv", "--strategy", "volt-var", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data["q_mvar"])[:3] == ["34.1", "70.1", "74.1"] and data["der_bus"]["34.1"] == "34"
    assert data["status"] == "ok" and data["max_vuf_pct"] > 0


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["snapshot", "eulv?der=nowhere.1:inverter:0.004", "--strategy", "llma"], "no such bus"),
        (["snapshot", "ieee13?der=611.1:inverter:0.05", "--strategy", "llma"], "phase 1"),
        (["snapshot", "ieee13?der=611.4:inverter:0.05", "--strategy", "llma"], "phases 1, 2, 3"),
        (["snapshot", f"opendss:{opendss_master('ieee13')}", "--strategy", "volt-var"], "no DER"),
    ],
)
def test_bad_der_on_a_feeder_exits_2(capsys, argv, expected):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


def test_lfma_reads_per_phase_flows_and_finds_the_upstream_line():
    """LFMA on ieee13 with single- and three-phase units: the line each branch-node DER
    takes as upstream (largest |Q| on its phases in the no-action state) is the one towards
    the source, and its step 3 adds that inflow to LLMA's setpoint (within the limit)."""
    from opfbench.strategies.paper import lfma_trace

    net = load_case(f"ieee13{IEEE13_DER},632.2:inverter:0.05").network
    assert isinstance(net, PhaseNetwork)
    scenario = Scenario.snapshot(net, 1.0, 0.5)
    res = run_strategy("lfma", scenario, 0.0)
    assert res.status[0] == "ok" and res.extra["upstream_disagreements"][0] == []
    trace = lfma_trace(scenario, 0.0)
    upstream = [net.bus_names[b] if b >= 0 else None for b in trace.upstream_branch[0]]
    assert upstream == [None, "670", None, None, "rg60"]  # 675, 611, 652 are leaves; 671 and 632 are fed from 670 and rg60
    limit = reactive_limit(scenario, 0.0)[0]
    expected = np.clip(trace.q_llma[0] + net.der_share * trace.q_up_h[0], -limit, limit)
    np.testing.assert_allclose(trace.q_step3[0, [1, 4]], expected[[1, 4]], rtol=1e-12)


def test_run_eulv_on_its_own_load_shapes_with_vuf_columns(tmp_path):
    """`opfbench run --case eulv`: every house on its own 1-min shape on the paper day (the
    loads OpenDSS's LoadShape gives, read here independently), the PV on the period's
    profile; the steps and summary carry the declared VUF columns; the frontier is drawn
    (`test_three_phase_leaderboard`) and the report is written."""
    import opendssdirect as dss
    import pandas as pd

    from opfbench.powerflow.multiphase import solve_phase_flow

    out = tmp_path / "run"
    argv = ["run", "--case", "eulv", "--strategies", "no-action", "volt-var", "--k", "0", "--night-modes", "connected"]
    argv += [
        "--forecast",
        "off",
        "--period",
        "2016-06-28T12:00..2016-06-28T12:09",
        "--workers",
        "1",
        "--quiet",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    steps = pd.read_parquet(out / "steps.parquet")
    summary = pd.read_csv(out / "summary.csv")
    assert (
        len(steps) == 18 and (steps.status == "ok").all()
    )  # 9 one-minute steps (the end is exclusive) × 2 and (out / "report.html").is_file()
    assert steps.max_vuf_pct.between(0.01, 5).all() and {"max_vuf_pct", "vuf_min"} <= set(summary.columns)
    worst = steps[steps.strategy == "no-action"].max_vuf_pct.max()
    assert summary.set_index("strategy").max_vuf_pct["no-action"] == pytest.approx(worst, rel=1e-5)  # CSV: 6 digits
    net = load_case("eulv").network
    with opendss_copy("eulv") as master:
        dss.Text.Command(f'compile "{master}"')
        mult = []
        i = dss.Loads.First()
        while i:
            dss.LoadShape.Name(dss.Loads.Yearly())
            mult.append(dss.LoadShape.PMult()[12 * 60 + 5])  # 12:05
            i = dss.Loads.Next()
    load_p = net.load_p_mw * np.array(mult)
    row = steps[(steps.strategy == "no-action") & (steps.time.dt.strftime("%H:%M") == "12:05")].iloc[0]
    from opfbench.study.task_scenarios import study_period

    period, _ = study_period(("eulv",), ("off",), "2016-06-28T12:00..2016-06-28T12:09", "20:00-05:00", None)
    pv_pu = period.profiles["pv"][row.time]  # the paper day's BSRN PV
    flow = solve_phase_flow(
        net, load_p[None], (load_p * net.load_q_mvar / net.load_p_mw)[None], (pv_pu * net.der_rating_mw)[None]
    )
    assert row.losses_kw == pytest.approx(flow.losses_kw[0], rel=1e-9)
    # the report's unbalance section: the VUF table and the profile at the worst no-action step
    page = (out / "report.html").read_text()
    section = page[page.index('id="unbalance"') :]
    assert "Worst VUF" in section and "profile-0" in section and "phase 3" in section
    from opfbench.report.profiles import worst_step

    worst = worst_step(steps, "eulv")
    base = steps[steps.strategy == "no-action"]
    assert worst in set(base.time) and worst.strftime("%Y-%m-%d %H:%M") in section
    deviation = np.fmax(base.vmax_pu - 1, 1 - base.vmin_pu)
    assert deviation[base.time == worst].iloc[0] == deviation.max()


def test_a_users_own_feeder_in_one_command_as_the_readme_gives_it(tmp_path):
    """The README's own-feeder command, taken from the README and run on a copy of the
    shipped ieee13 master (a shorter period, no frontier: the rules alone): every rule runs on the listed DER, named
    `BUS.PHASES`, and the run writes its tables and report."""
    import shlex
    from pathlib import Path

    import pandas as pd

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    line = next(l for l in readme.splitlines() if "opfbench run --case opendss:my/Master.dss --der" in l)
    argv = shlex.split(line[line.index("opfbench run") : line.rindex("`")])[1:]
    out = tmp_path / "mine"
    with opendss_copy("ieee13") as master:
        argv = [str(master) if a == "opendss:my/Master.dss" else a for a in argv]
        argv = [f"opendss:{a}" if a == str(master) else a for a in argv]
        extra = ["--period", "2016-06-28T12:00..2016-06-28T12:02", "--k", "0", "--night-modes", "connected", "--no-frontier"]
        assert main([*argv, *extra, "--forecast", "off", "--workers", "1", "--quiet", "--out", str(out)]) == 0
    steps = pd.read_parquet(out / "steps.parquet")
    strategies = argv[argv.index("--strategies") + 1 :]
    assert sorted(steps.strategy.unique()) == sorted(strategies) and len(steps) == 2 * len(strategies)
    assert (steps.status == "ok").all() and (out / "report.html").is_file()
    der = pd.read_parquet(out / "der_q.parquet")
    buses = [item.split(":")[0] for item in argv[argv.index("--der") + 1].split(",")]
    assert set(der.der) == {b if "." in b else f"{b}.1.2.3" for b in buses}  # a bus without phases: all of ieee13's three


@pytest.mark.parametrize(("name", "meter"), [("ieee13", "Line.650632"), ("ieee123", "Line.L115")])
def test_bus_distance_is_opendss_own(name, meter):
    """The profile's x axis: each bus's distance from the source equals OpenDSS's own
    (`Bus.Distance` from an energy meter at the feeder head) within 0.5 %."""
    import opendssdirect as dss

    net = load_case(name).network
    assert isinstance(net, PhaseNetwork)
    dist, upstream = net.bus_distance
    with opendss_copy(name) as master:
        dss.Text.Command(f'compile "{master}"')
        dss.Text.Command(f"new energymeter.head element={meter} terminal=1")
        dss.Solution.Solve()
        theirs = {}
        for bus in dss.Circuit.AllBusNames():
            dss.Circuit.SetActiveBus(bus)
            theirs[bus.lower()] = dss.Bus.Distance()
    zone = [i for i, b in enumerate(net.bus_names) if theirs[b] > 0]
    assert len(zone) > 10
    assert dist[zone] == pytest.approx([theirs[net.bus_names[i]] for i in zone], rel=5e-3)
    assert upstream[net.source.bus] == -1 and (upstream[zone] >= 0).all()
