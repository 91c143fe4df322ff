"""The closed-loop rules against independent engines: OpenDSS's InvControl VOLTVAR (through
opendssdirect.py; `tests/support/opendss_oracle.py`) and pandapower's DERController
(Q(V) and cos φ(P) curves) — Q per DER within 1e-6 MVAr, |V| within 1e-7 p.u., losses
within 1e-4 kW; Volt-Watt, Volt-VAR + Volt-Watt and reactive priority against OpenDSS's
InvControl VOLTWATT (VoltwattYAxis=PMPPPU), CombiMode=VV_VW and PVSystem WattPriority=no
where curtailment binds — P and Q per DER within 1e-6 p.u. of S̄. Operating points: heavy load and little sun (the rules inject, the PV's
limits bind), nominal load at 80 % output (inject, no limit binding), light load at 90 %
output (voltages above 1.02 p.u.: the rules absorb); Category A and B; k = 0 and 0.4.
The full sweep on paper33 and case69-der is slow; a representative subset runs by default."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pandapower as pp
import pytest
from pandapower.control import run_control
from pandapower.control.controller.DERController import (
    CosphiPCurve,
    DERController,
    QModelCosphiPCurve,
    QModelQVCurve,
    QVCurve,
)
from pandapower.converter.pypower import from_ppc

from opfbench.capability import q_peak
from opfbench.io import load_network
from opfbench.io.matpower import to_ppc
from opfbench.registry.catalog import configuration, run_strategy
from opfbench.scenario import Scenario
from opfbench.strategies.limits import Capability, reactive_limit
from opfbench.strategies.standards import VOLT_VAR, VOLT_WATT
from tests.support.opendss_oracle import Unit, opendss_inverters, opendss_volt_var

TOL_Q_MVAR, TOL_V_PU, TOL_LOSS_KW = 1e-6, 1e-7, 1e-4
POINTS = {  # load scale, DER output share, what the rules do there
    "inject-bind": (1.3, 0.2),
    "inject": (1.0, 0.8),
    "absorb": (0.1, 0.9),
}
SWEEP = list(itertools.product(("paper33", "case69-der"), POINTS, ("a", "b"), (0.0, 0.4)))
DEFAULT = {("paper33", "inject-bind", "b", 0.4), ("paper33", "inject", "a", 0.0), ("paper33", "absorb", "b", 0.0)}
DEFAULT |= {("case69-der", "inject-bind", "a", 0.0)}


def _against_opendss(case: str, point: str, curve: str, k: float, points: tuple | None = None):
    net = load_network(case)
    scenario = Scenario.snapshot(net, *POINTS[point])
    v, q = points or VOLT_VAR[curve]
    label = f"volt-var:v={'/'.join(map(str, v))},q={'/'.join(map(str, q))}" if points else f"volt-var:curve={curve}"
    ours = run_strategy(label, scenario, k)
    limit = reactive_limit(scenario, k)[0]
    load = scenario.bus_load_mva()[0]
    theirs = opendss_volt_var(net, load.real, load.imag, scenario.der_p_mw[0], limit, v, q, net.der_s_mva)
    assert theirs.converged and ours.status[0] == "ok"
    np.testing.assert_allclose(theirs.p_mw, scenario.der_p_mw[0], atol=1e-9)  # the PVSystems produce our P
    assert np.abs(theirs.q_mvar - ours.q_mvar[0]).max() < TOL_Q_MVAR
    assert np.abs(theirs.vm - ours.vm[0]).max() < TOL_V_PU
    assert abs(theirs.losses_kw - ours.losses_kw[0]) < TOL_LOSS_KW
    return ours, limit


@pytest.mark.parametrize(
    "case, point, curve, k", [c if c in DEFAULT else pytest.param(*c, marks=pytest.mark.slow) for c in SWEEP]
)
def test_volt_var_steady_state_equals_opendss_invcontrol(case, point, curve, k):
    ours, limit = _against_opendss(case, point, curve, k)
    q = ours.q_mvar[0]
    if point == "absorb":
        assert (q < -1e-4).any() and (q <= 1e-12).all()
    else:
        assert (q > 1e-4).any() and (q >= -1e-12).all()
    if point == "inject-bind" and case == "paper33":
        assert np.isclose(np.abs(q), limit, rtol=0, atol=TOL_Q_MVAR).any()  # the PV's power-factor limit binds


def test_a_steep_curve_settles_where_opendss_settles():
    """Volt-VAR from +0.44 to −0.44 p.u. within 0.01 p.u. (undamped it does not settle:
    `test_strategies_standards`): our damped answer is OpenDSS's."""
    _against_opendss("paper33", "inject", "b", 0.0, points=((0.965, 0.975), (0.44, -0.44)))


class _TightDERController(DERController):
    """pandapower's DERController with its convergence test absolute (its own compares with
    numpy's default relative tolerance of 1e-5, i.e. ~2e-6 MVAr here)."""

    def is_converged(self, net) -> bool:
        self._determine_target_powers(net)
        return bool(
            np.allclose(self.target_q_mvar, self.q_mvar, rtol=0, atol=self.max_q_error)
            and np.allclose(self.target_p_mw, self.p_mw, rtol=0, atol=self.max_p_error)
        )


def _pandapower(net, scenario: Scenario, q_model):
    """The DERs as pandapower sgens (P, S̄ = sn_mva) under one DERController."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pnet = from_ppc(to_ppc(net), f_hz=50)
    pnet.load[["p_mw", "q_mvar"]] *= float(scenario.load_scale[0])
    ids = net.bus_ids[net.der_bus]
    sgens = [
        pp.create_sgen(pnet, int(b), p_mw=float(p), q_mvar=0.0, sn_mva=float(s))
        for b, p, s in zip(ids, scenario.der_p_mw[0], net.der_s_mva, strict=True)
    ]
    _TightDERController(pnet, sgens, q_model=q_model, pqv_area=None, damping_coef=2, max_q_error=1e-10, max_p_error=1e-10)
    run_control(pnet, max_iter=200, tolerance_mva=1e-10, numba=False, init="flat")
    return pnet.res_sgen.q_mvar.to_numpy(), pnet.res_bus.vm_pu.to_numpy()


@pytest.mark.parametrize(
    "point, curve",
    [
        ("inject", "a"),
        ("absorb", "b"),
        pytest.param("inject", "b", marks=pytest.mark.slow),
        pytest.param("absorb", "a", marks=pytest.mark.slow),
    ],
)
def test_volt_var_and_cosphi_p_equal_pandapower_der_controller(point, curve):
    """Where the limits do not bind (the DERController here has none): Volt-VAR as
    QModelQVCurve (Q in p.u. of sn_mva = S̄), VDE 4105 cos φ(P) as QModelCosphiPCurve
    (under-excited = negative cos φ in pandapower's convention)."""
    net = load_network("paper33")
    scenario = Scenario.snapshot(net, *POINTS[point])
    ours = run_strategy(f"volt-var:curve={curve}", scenario, 0.0)
    assert (np.abs(ours.q_mvar[0]) < reactive_limit(scenario, 0.0)[0] - 1e-3).all()
    q, vm = _pandapower(net, scenario, QModelQVCurve(QVCurve(*VOLT_VAR[curve])))
    assert np.abs(q - ours.q_mvar[0]).max() < TOL_Q_MVAR and np.abs(vm - ours.vm[0]).max() < TOL_V_PU
    ours = run_strategy("cosphi-p", scenario, 0.0)
    q, vm = _pandapower(net, scenario, QModelCosphiPCurve(CosphiPCurve([0.0, 0.5, 1.0], [1.0, 1.0, -0.9])))
    assert (ours.q_mvar[0] < -0.1).all()
    assert np.abs(q - ours.q_mvar[0]).max() < TOL_Q_MVAR and np.abs(vm - ours.vm[0]).max() < TOL_V_PU


# ----- active power: Volt-Watt, VV_VW, reactive priority ------------------------------------
PEAK_PF = {"PV": 0.8, "inverter": 0.9}  # cos φ where each kind's Qmax(P) peaks (`capability`)


def _units(net, scenario: Scenario) -> list[Unit]:
    """Our DER as OpenDSS PVSystems with their own capability: kVA = S̄, Pmpp = P̄, kvarMax the
    peak of Qmax and %PminkvarMax the power where it peaks (the power-factor line below it).
    A DFIG's falling curve has no PVSystem counterpart: it gets kvarMax = Qmax at the power
    it has and a kVA that never binds (the test checks its limit does not bind)."""
    out = []
    for d, (kind, rating, s) in enumerate(zip(net.der_kinds, net.der_rating_mw, net.der_s_mva, strict=True)):
        p_kw = float(scenario.der_p_mw[0, d]) * 1e3
        if kind == "DFIG":
            out.append(Unit(10 * s * 1e3, rating * 1e3, p_kw, float(scenario.qmax_mvar()[0, d]) * 1e3))
            continue
        peak_p = min(PEAK_PF[kind] * s, rating)
        peak_q = float(q_peak([kind], np.array([rating]), np.array([rating]), np.array([s]))[0])
        out.append(Unit(s * 1e3, rating * 1e3, p_kw, peak_q * 1e3, 100 * peak_p / rating))
    return out


ACTIVE = {  # case, configuration at load 0 and full output (k = 0): curtailment binds
    "paper33 volt-watt": ("paper33", "volt-watt"),
    "paper33 vv_vw": ("paper33", "volt-var+volt-watt"),
    "paper33 q-priority": ("paper33", "volt-var:priority=q"),
    "paper33 vv_vw q-priority": ("paper33", "volt-var+volt-watt:curve=a,priority=q"),
    "case69-der volt-watt": ("case69-der", "volt-watt:v=1.03/1.06,p=1/0"),
    "case69-der vv_vw": ("case69-der", "volt-var+volt-watt:vw_v=1.03/1.06,vw_p=1/0"),
    "case69-der q-priority": ("case69-der", "volt-var:curve=a,priority=q"),
}


@pytest.mark.parametrize("name", ACTIVE)
def test_volt_watt_and_priority_equal_opendss_where_curtailment_binds(name):
    case, label = ACTIVE[name]
    net = load_network(case)
    scenario = Scenario.snapshot(net, 0.0, 1.0)
    ours = run_strategy(label, scenario, 0.0)
    options = configuration(label).options()
    volt_var = volt_watt = None
    if "q" in options:
        volt_var = (options["v"], options["q"]) if options["v"] else VOLT_VAR[options["curve"]]
    if "vw_p" in options or "p" in options:
        v, p = (options["vw_v"], options["vw_p"]) if "vw_p" in options else (options["v"], options["p"])
        volt_watt = (v, p) if v else VOLT_WATT
    load = scenario.bus_load_mva()[0]
    q_priority = options["priority"] == "q"
    theirs = opendss_inverters(
        net, load.real, load.imag, _units(net, scenario), volt_var, volt_watt, net.der_s_mva, not q_priority
    )
    assert theirs.converged and ours.status[0] == "ok" and ours.curtailed_mw is not None
    p_ours = scenario.der_p_mw[0] - ours.curtailed_mw[0]
    assert (ours.curtailed_mw[0] > 1e-3).any()  # curtailment binds
    if q_priority:
        assert (np.abs(ours.q_mvar[0]) > 1e-3).any()
    s_bar = net.der_s_mva
    assert np.abs(theirs.p_mw - p_ours).max() / s_bar.min() < 1e-6
    assert np.abs(theirs.q_mvar - ours.q_mvar[0]).max() / s_bar.min() < 1e-6
    assert np.abs(theirs.vm - ours.vm[0]).max() < TOL_V_PU
    dfig = np.array(net.der_kinds) == "DFIG"  # its limit (represented at P^C only) must not bind
    limit = Capability(scenario, 0.0, priority=options["priority"]).limit(np.arange(1), p_ours[None, :])[0]
    assert (np.abs(ours.q_mvar[0][dfig]) < np.minimum(limit, scenario.qmax_mvar()[0])[dfig] - 1e-3).all()
