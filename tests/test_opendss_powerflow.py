"""The three-phase power flow against OpenDSS (`tests/support/opendss_feeders.py`: the
shipped master compiled and solved by OpenDSS alone at tolerance 1e-10): every node's |V|
within 1e-6 p.u. and the losses within 1e-4 relative — at the file's own snapshot and at
three time-series steps with the feeder's DER at fixed output (the small feeders by
default, every shipped feeder under `-m slow`), at other load levels with the regulator
taps held (loads of status fixed or exempt at their nominal), and with PVSystems and
Generators of a file of its own."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import pvsystem_lines
from opfbench.data import paper_day
from opfbench.io import load_case
from opfbench.io.opendss import read_opendss, shape_series
from opfbench.multiphase import PhaseNetwork
from opfbench.powerflow.multiphase import solve_phase_flow
from tests.support.opendss_feeders import (
    UNBALANCED_ALL,
    UNBALANCED_SMALL,
    bus_vuf,
    held_taps,
    line_impedance_ohm,
    pv_output,
    solve,
    solve_time_step,
)

V_TOL_PU = 1e-6
LOSS_REL = 1e-4


def _network(name: str) -> tuple[PhaseNetwork, tuple]:
    case = load_case(name)
    assert isinstance(case.network, PhaseNetwork) and case.stored is not None
    return case.network, case.stored


def _agrees(net: PhaseNetwork, ours, theirs, row: int = 0) -> tuple[float, float]:
    """Snapshot `row` of our flow against OpenDSS's; returns (max |ΔV| p.u., relative loss error)."""
    assert theirs.converged and bool(ours.converged[row])
    assert theirs.node_names == list(net.node_names)
    dv = np.abs(ours.v[row] - theirs.v) / net.node_base_v
    worst = int(dv.argmax())
    assert dv.max() < V_TOL_PU, f"{net.name}: |ΔV| {dv.max():.2e} p.u. at {net.node_names[worst]}"
    assert ours.losses_kw[row] == pytest.approx(theirs.losses_kw, rel=LOSS_REL)
    return float(dv.max()), abs(ours.losses_kw[row] / theirs.losses_kw - 1.0)


def _own_snapshot(name: str) -> None:
    net, (load_p, load_q, der_p, der_q) = _network(name)
    ours = solve_phase_flow(net, load_p[None], load_q[None], der_p[None], der_q[None])
    with opendss_copy(name) as master:
        theirs = solve(master)
    _agrees(net, ours, theirs)


@pytest.mark.parametrize("name", UNBALANCED_SMALL)
def test_the_files_own_snapshot_is_opendss(name):
    _own_snapshot(name)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in UNBALANCED_ALL if n not in UNBALANCED_SMALL])
def test_the_large_feeders_own_snapshot_is_opendss(name):
    _own_snapshot(name)


def _other_load_level(name: str, load_mult: float) -> None:
    net, _ = _network(name)
    ours = solve_phase_flow(net, *net.loads_at(load_mult))
    with opendss_copy(name) as master:
        theirs = solve(master, f"set loadmult={load_mult!r}", *held_taps(net), controls=False)
    _agrees(net, ours, theirs)
    if load_mult > 1.3:  # the case the switch to impedance matters for
        assert (ours.node_vm_pu[0][net.load_branches.a] < 0.95).any()


@pytest.mark.parametrize(("name", "load_mult"), [("ieee13", 0.4), ("ieee13", 1.35), ("ieee123", 1.6), ("ieee37", 0.7)])
def test_other_load_levels_with_the_taps_held(name, load_mult):
    """Loads scaled (OpenDSS's loadmult): the models' switches to impedance below vminpu
    and above vmaxpu, constant Z and I and the CVR exponents all take part."""
    _other_load_level(name, load_mult)


@pytest.mark.slow
@pytest.mark.parametrize("load_mult", [0.3, 0.9, 1.4])
def test_ieee8500_at_other_load_levels_keeps_its_fixed_loads(load_mult):
    """ieee8500's 24 loads of `status=fixed` stay at their nominal under OpenDSS's
    loadmult (read as `load_fixed`; scaling them too put |V| 1e-2 p.u. off at 0.9)."""
    assert _network("ieee8500")[0].load_fixed.sum() == 24
    _other_load_level("ieee8500", load_mult)


def test_loads_of_status_fixed_or_exempt_keep_their_nominal(tmp_path):
    """A load of status fixed or exempt stays at its nominal under a load multiplier
    (OpenDSS's `Load.SetNominalLoad`); the others follow it — as OpenDSS solves it."""
    with opendss_copy("ieee13") as master:
        file = tmp_path / "fixed.dss"
        file.write_text(f'redirect "{master}"\nedit load.671 status=fixed\nedit load.692 status=exempt\n')
        net = load_case(f"opendss:{file}").network
        assert isinstance(net, PhaseNetwork)
        assert [net.load_names[i] for i in np.flatnonzero(net.load_fixed)] == ["Load.671", "Load.692"]
        p, q = net.loads_at(np.array([0.5, 1.0]))
        assert p[0] == pytest.approx(np.where(net.load_fixed, 1.0, 0.5) * net.load_p_mw)
        assert q[1] == pytest.approx(net.load_q_mvar)
        ours = solve_phase_flow(net, p[:1], q[:1])
        theirs = solve(file, "set loadmult=0.5", *held_taps(net), controls=False)
    _agrees(net, ours, theirs)


def test_a_fixed_load_keeps_its_nominal_on_its_shape(tmp_path):
    """On a feeder's own shapes (`shape_series`) a load of status fixed stays at its
    nominal; one of status exempt still follows its shape (OpenDSS's time modes)."""
    with opendss_copy("eulv") as master:
        file = tmp_path / "fixed.dss"
        file.write_text(f'redirect "{master}"\nedit load.load1 status=fixed\nedit load.load2 status=exempt\n')
        circuit = read_opendss(file)
    series = shape_series(circuit, "2016-06-28", "Europe/Berlin", "test")
    load_p, load_q, _ = series.rows(series.index[[300, 700]])
    assert load_p[:, 0] == pytest.approx([circuit.load_p_mw[0]] * 2) and load_q[:, 0] == pytest.approx(
        [circuit.load_q_mvar[0]] * 2
    )
    assert load_p[:, 1] == pytest.approx(circuit.shapes[circuit.load_shapes[1]].p[[300, 700]] * circuit.load_p_mw[1])


STEPS = ("03:00", "11:00", "13:00")
"""Three time-series steps (local time): night (no PV, light load), near the paper day's
load peak (10:45), high PV."""
SHAPED = {"eulv": ("2016-06-28", STEPS), "ckt24": ("2016-07-15", ("03:00", "14:00", "19:00"))}
"""The day and steps of the feeders on their own load shapes (eulv: the paper day; ckt24:
a summer day of its year, night, high PV, evening peak)."""
SEVERAL_POINTS = {"ckt24": ("03:00", "19:00")}
"""Steps at which the feeder has more than one operating point. ckt24's CVR loads (model 4)
switch to an impedance above vmaxpu = 1.05 with a jump — OpenDSS's own load model: P·u^0.8
just below, P·u²/1.05² just above —, so where their voltages reach 1.05 p.u. two states
solve the same equations: OpenDSS's iteration lands on one, ours from the no-load start
on another (up to 3e-3 p.u. apart on this day, every hour whose |V| passes 1.05; which one
follows from the iteration matrix: OpenDSS's holds the loads' admittance at the step's
level, ours at the nominal — built at the step's level, ours lands on OpenDSS's too).
There ours starts from OpenDSS's state; agreeing to 1e-6 then says it is one of ours."""


def _time_steps(name: str) -> dict[str, tuple[float, float]]:
    """The shipped feeder `name` with its DER (its placement rule, `pv_on_loads`) at three
    time-series steps against OpenDSS with the same PVSystems at fixed output: loads on
    the paper day's load profile (OpenDSS's loadmult) — or on the feeder's own shapes
    (OpenDSS's yearly mode at that step) —, PV P at the paper day's PV profile at the same
    clock time, Q ±0.2 S̄ (alternating: absorbing, injecting). Ours: one batched flow
    (from OpenDSS's state at `SEVERAL_POINTS`). Returns each step's (max |ΔV| p.u.,
    relative loss error)."""
    case = load_case(name)
    net = case.network
    assert isinstance(net, PhaseNetwork) and net.ders
    day = paper_day()
    date, steps = SHAPED.get(name, ("", STEPS))
    at = [day.index[(day.index.hour == int(t[:2])) & (day.index.minute == int(t[3:]))][0] for t in steps]
    der_p = day.loc[at, "pv"].to_numpy()[:, None] * net.der_rating_mw
    der_q = np.tile(0.2 * net.der_s_mva * (-1.0) ** (np.arange(len(net.ders)) + 1), (len(steps), 1))
    if case.series is None:
        load = day.loc[at, "load"].to_numpy()
        load_p, load_q = net.loads_at(load)
        when = [{"load_mult": float(x)} for x in load]
    else:
        series = case.series
        times = pd.DatetimeIndex([pd.Timestamp(f"{date} {t}").tz_localize(series.index.tz) for t in steps])
        load_p, load_q, _ = series.rows(times)
        points = series.index.get_indexer(times)
        assert (points >= 0).all()
        when = [
            {"hour": float((k + 1) * series.step / pd.Timedelta(hours=1))} for k in points
        ]  # OpenDSS: point k+1 at (k+1)·step
    ours = solve_phase_flow(net, load_p, load_q, der_p, der_q)
    out = {}
    with opendss_copy(name) as master:
        for s, (t, kw) in enumerate(zip(steps, when, strict=True)):
            theirs = solve_time_step(master, pvsystem_lines(net, der_p[s], der_q[s]), **kw)
            assert pv_output() == pytest.approx(np.column_stack([der_p[s], der_q[s]]) * 1e3, abs=1e-6)  # the DER as given
            if t in SEVERAL_POINTS.get(name, ()):
                row = np.s_[s : s + 1]
                started = solve_phase_flow(net, load_p[row], load_q[row], der_p[row], der_q[row], v0=theirs.v[None])
                out[t] = _agrees(net, started, theirs)
            else:
                out[t] = _agrees(net, ours, theirs, s)
    assert der_p[0].max() == 0 and der_p.max() > 0  # a night step, and PV output
    return out


@pytest.mark.parametrize("name", UNBALANCED_SMALL)
def test_time_series_steps_with_der_are_opendss(name):
    _time_steps(name)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in UNBALANCED_ALL if n not in UNBALANCED_SMALL])
def test_time_series_steps_with_der_on_the_other_feeders_are_opendss(name):
    _time_steps(name)


DER_LINES = (
    "new pvsystem.pv675a phases=1 bus1=675.1 kv=2.4 kva=300 pmpp=250 irradiance=1 pf=1 vminpu=0.5 vmaxpu=1.5",
    "new pvsystem.pv680 phases=3 bus1=680 kv=4.16 kva=500 pmpp=400 irradiance=0.8 kvar=-60 vminpu=0.5 vmaxpu=1.5",
    "new pvsystem.pv684 phases=1 bus1=684.1.3 conn=delta kv=4.16 kva=100 pmpp=80 irradiance=1 kvar=20 vminpu=0.5 vmaxpu=1.5",
    "new generator.g671 phases=3 bus1=671 kv=4.16 kw=300 kvar=50 model=1 vminpu=0.5 vmaxpu=1.5",
)


def _with_der(tmp_path, master) -> object:
    file = tmp_path / "with_der.dss"
    file.write_text("\n".join([f'redirect "{master}"', *DER_LINES, "set voltagebases=[115, 4.16, .48]", "calcv"]) + "\n")
    return file


def test_pvsystems_and_generators_of_a_file_are_der_and_solve_as_opendss(tmp_path):
    with opendss_copy("ieee13") as master:
        file = _with_der(tmp_path, master)
        case = load_case(f"opendss:{file}")
        net = case.network
        assert isinstance(net, PhaseNetwork) and case.stored is not None
        assert net.der_names == ("PVSystem.pv675a", "PVSystem.pv680", "PVSystem.pv684", "Generator.g671")
        assert [d.rating_mw for d in net.ders] == pytest.approx([0.25, 0.4, 0.08, 0.3])
        assert [d.s_rated_mva for d in net.ders] == pytest.approx([0.3, 0.5, 0.1, 0.36])  # a Generator: kVA 1.2·kW by default
        assert net.der_branches.n == 1 + 3 + 1 + 3
        load_p, load_q, der_p, der_q = case.stored
        assert der_p == pytest.approx([0.25, 0.32, 0.08, 0.3], rel=1e-9)
        assert der_q == pytest.approx([0.0, -0.06, 0.02, 0.05], abs=1e-9)
        ours = solve_phase_flow(net, load_p[None], load_q[None], der_p[None], der_q[None])
        theirs = solve(file)
    _agrees(net, ours, theirs)


def test_vuf_is_opendss_sequence_voltages():
    net, (load_p, load_q, der_p, der_q) = _network("ieee13")
    ours = solve_phase_flow(net, load_p[None], load_q[None])
    with opendss_copy("ieee13") as master:
        solve(master)
        buses = [net.bus_names[net.node_bus[row[0]]] for row in net.three_phase_nodes]
        theirs = np.array([bus_vuf(b) for b in buses])
    assert ours.vuf[0] == pytest.approx(theirs, abs=1e-8)
    assert theirs.max() > 0.01  # an unbalanced feeder: the check has something to see


def test_line_impedance_matrices_are_opendss_own():
    """Z from the element's primitive admittance equals OpenDSS's R + jX × length."""
    net, _ = _network("ieee13")
    with opendss_copy("ieee13") as master:
        solve(master)
        for line in net.lines:
            name = net.elements[line.element].name.split(".", 1)[1]
            if not line.switch:
                assert line.z_ohm == pytest.approx(line_impedance_ohm(name), rel=1e-9, abs=1e-12), name
    lengths = {net.elements[line.element].name: line.length_km for line in net.lines}
    assert lengths["Line.650632"] == pytest.approx(2000 * 0.3048e-3)


def test_the_band_applies_phase_to_phase_on_three_wire_delta_sections():
    delta, _ = _network("ieee37")
    names = delta.monitored[3]
    assert "701.1-2" in names and "701.1" not in names  # 4.8 kV three-wire delta
    assert "sourcebus.1" in names  # the source's wye-grounded side
    wye, _ = _network("ieee13")
    assert all("-" not in n for n in wye.monitored[3]) and "671.1" in wye.monitored[3]
    assert wye.band == (0.95, 1.05) and _network("eulv")[0].band == (0.90, 1.10)


def test_a_diverging_snapshot_is_counted_and_gives_no_convergence():
    """Loads far beyond what the feeder can carry: the iteration does not settle, and the
    snapshot says so (the ones beside it still solve)."""
    net, _ = _network("ieee13")
    scale = np.array([1.0, 60.0])[:, None]
    res = solve_phase_flow(net, net.load_p_mw[None] * scale, net.load_q_mvar[None] * scale)
    assert res.converged.tolist() == [True, False]


@pytest.mark.parametrize("name", ["ieee13", "ieee123"])
def test_a_batch_is_its_snapshots_one_by_one_and_a_warm_start_changes_nothing(name):
    """Snapshots are independent columns (the dense path on ieee13's few load nodes, the
    same on ieee123): solved together or alone, cold or warm, they agree to the tolerance."""
    net, _ = _network(name)
    scale = np.array([0.3, 1.0, 1.4])[:, None] * np.linspace(0.8, 1.2, net.n_load)[None, :]
    batch = solve_phase_flow(net, net.load_p_mw * scale, net.load_q_mvar * scale)
    assert batch.converged.all()
    for s in range(3):
        alone = solve_phase_flow(net, net.load_p_mw[None] * scale[s], net.load_q_mvar[None] * scale[s])
        assert np.abs(alone.v[0] - batch.v[s]).max() / net.node_base_v.min() < 1e-9
    warm = solve_phase_flow(net, net.load_p_mw * scale, net.load_q_mvar * scale, v0=batch.v)
    assert warm.iterations.max() <= 2 and np.abs(warm.v - batch.v).max() / net.node_base_v.min() < 1e-9


def test_a_warm_start_column_not_finite_or_all_zero_starts_from_no_load():
    """Snapshots whose v0 holds a NaN, an inf or only zeros start from the no-load state —
    the cold solve's iterations and voltages —, the others from their v0."""
    net, _ = _network("ieee13")
    scale = np.array([0.3, 1.0, 1.4, 0.7])[:, None] * np.ones(net.n_load)[None, :]
    cold = solve_phase_flow(net, net.load_p_mw * scale, net.load_q_mvar * scale)
    v0 = cold.v.copy()
    node = int(net.load_branches.a[0])  # a node the iteration carries
    v0[0, node], v0[1, node], v0[2] = np.nan, np.inf, 0.0
    warm = solve_phase_flow(net, net.load_p_mw * scale, net.load_q_mvar * scale, v0=v0)
    assert warm.converged.all()
    np.testing.assert_array_equal(warm.iterations[:3], cold.iterations[:3])
    np.testing.assert_allclose(warm.v[:3], cold.v[:3], rtol=1e-12, atol=0)
    assert warm.iterations[3] < cold.iterations[3]
