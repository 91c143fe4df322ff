"""ieee8500's AC OPF snapshot of `bench unbalanced --large` (`bench.unbalanced_opf`): its
inputs (loads through `loads_at`, the taps the power flow's control settles, held), the
reason it is the paper day's noon (the band reachable there, out of reach at the PV
peak), and — slow — the OPF's confirmed optimum there, by our power flow and by OpenDSS."""

import numpy as np
import pytest

from opfbench.bench.unbalanced_opf import LARGE_AT, ieee8500, ieee8500_snapshot
from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import pvsystem_lines
from opfbench.formulations.three_phase import optimum, q_limits
from opfbench.io import load_case
from opfbench.powerflow.multiphase import solve_phase_flow
from opfbench.result import OK
from tests.support.opendss_feeders import set_tap, solve

PV_PEAK = "14:48"  # the paper day's minute of the largest PV output


@pytest.fixture(scope="module")
def noon():
    return ieee8500_snapshot(LARGE_AT)


def test_snapshot_scales_loads_but_the_fixed_ones(noon):
    net, load_p, load_q, _, load, _, _ = noon
    assert net.load_fixed.sum() == 24 and 0.5 < load < 1.0
    mult = np.where(net.load_fixed, 1.0, load)
    assert load_p[0] == pytest.approx(mult * net.load_p_mw, rel=1e-15)
    assert load_q[0] == pytest.approx(mult * net.load_q_mvar, rel=1e-15)


def test_snapshot_holds_the_taps_the_control_settles(noon):
    net, load_p, load_q, der_p, _, _, taps = noon
    controlled = load_case("ieee8500?taps=control").network
    settled = solve_phase_flow(controlled, load_p, load_q, der_p)
    assert not net.tap_control and settled.tap_positions is not None
    assert taps == tuple(settled.tap_positions[0].tolist()) and len(taps) == 12
    assert taps != tuple(r.settled for r in controlled.regulators)  # not the file's (settled at full load)
    held = solve_phase_flow(net, load_p, load_q, der_p)
    assert held.converged[0] and np.max(np.abs(held.v - settled.v) / net.node_base_v) < 1e-9


def _absorbing(at: str):
    """The flow at `at` with the taps held as settled and every DER absorbing its whole Q."""
    net, load_p, load_q, der_p, _, _, _ = ieee8500_snapshot(at)
    names = np.array(net.monitored[3])
    none = solve_phase_flow(net, load_p, load_q, der_p)
    full = solve_phase_flow(net, load_p, load_q, der_p, -q_limits(net, der_p, 0.0))
    assert none.converged[0] and full.converged[0]
    return net, names, none.vm[0], full.vm[0]


def test_noon_band_is_reachable_by_absorbing_q():
    """No action leaves the band at noon; every DER absorbing its whole Q is a point within
    it — the OPF's feasible set is not empty."""
    net, _, none, full = _absorbing(LARGE_AT)
    lo, hi = net.band
    assert none.max() > hi + 1e-3
    assert lo <= full.min() and full.max() <= hi + 1e-9


def test_pv_peak_band_is_out_of_reach_at_the_substation():
    """At the PV peak the substation's 12.47 kV bus (the feeder regulator's terminals) stays
    above the band even with every DER absorbing its whole Q: the regulator's band (vreg
    126.5 ± 1 V on 120 V) lets it sit there at light load."""
    net, names, none, full = _absorbing(PV_PEAK)
    hi = net.band[1]
    assert full.max() > hi + 1e-3 and "hvmv_sub" in names[full.argmax()]
    assert full.max() < none.max()  # absorbing lowers it, not enough
    reg = net.regulators[0]  # feeder_rega: its set point (V on the PT's secondary) is above the band
    assert reg.name == "feeder_rega" and reg.vreg > hi * reg.base_v / reg.pt_ratio


@pytest.mark.slow
def test_ieee8500_opf_reaches_a_confirmed_optimum_at_noon():
    figures = ieee8500()
    assert figures["ieee8500_opf_status"] == OK and figures["ieee8500_opf_ipopt_status"] == "Solve_Succeeded"
    lo, hi = 0.95, 1.05
    assert lo - 1e-6 <= figures["ieee8500_opf_vmin_pu"] and figures["ieee8500_opf_vmax_pu"] <= hi + 1e-6
    assert figures["ieee8500_no_action_vmax_pu"] > hi  # the band binds: the optimum had to act
    assert figures["ieee8500_opf_q_mvar"] < 0  # by absorbing Q
    assert np.isfinite(figures["ieee8500_opf_losses_kw"]) and figures["ieee8500_opf_pf_ratio"] > 1


@pytest.mark.slow
def test_ieee8500_noon_optimum_is_opendss():
    """The noon optimum's Q put into OpenDSS (fixed kvar on the same PV units, its taps at
    the held positions, controls off): every node as ours within 1e-6 p.u., the losses
    within 1e-6 relative, every monitored voltage within the band."""
    net, load_p, load_q, der_p, load, _, taps = ieee8500_snapshot(LARGE_AT)
    opt = optimum(net, load_p, load_q, der_p, 0.0)
    assert opt.status[0] == OK
    q = opt.q_mvar[0]
    assert np.all(np.abs(q) <= q_limits(net, der_p, 0.0)[0] + 1e-12)
    ours = solve_phase_flow(net, load_p, load_q, der_p, q[None])
    assert ours.losses_kw[0] == pytest.approx(opt.losses_kw[0], rel=1e-12)
    tap_commands = [
        set_tap(net.elements[reg.element].name.split(".", 1)[1], reg.tap_winding, float(reg.taps[pos]))
        for reg, pos in zip(net.regulators, taps, strict=True)
    ]
    with opendss_copy("ieee8500") as master:
        theirs = solve(master, f"set loadmult={load!r}", *tap_commands, *pvsystem_lines(net, der_p[0], q), controls=False)
    assert theirs.converged and theirs.node_names == list(net.node_names)
    assert np.max(np.abs(ours.v[0] - theirs.v) / net.node_base_v) < 1e-6
    assert theirs.losses_kw == pytest.approx(opt.losses_kw[0], rel=1e-6)
    a, b, base, _ = net.monitored
    v = np.append(theirs.v, 0.0)  # GROUND (−1) reads the appended 0 V
    vm = np.abs(v[a] - v[b]) / base
    lo, hi = net.band
    assert lo - 1e-6 <= vm.min() and vm.max() <= hi + 1e-6
