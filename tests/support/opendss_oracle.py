"""OpenDSS (through `opendssdirect.py`) as an independent, test-time-only oracle of the
closed-loop inverter rules' steady state: our network as a balanced three-phase OpenDSS
circuit (a stiff source at the slack's voltage, lines from the branches' R and X in ohms,
loads at constant power with a low vminpu so they never turn to impedance), every DER a
PVSystem (constant power too: low vminpu) with an InvControl per DER — adaptive step
factors (deltaQ_factor and deltaP_factor −1, as our engine), tight VarChangeTolerance,
VoltageChangeTolerance and ActivePChangeTolerance, a tight solution tolerance.

`opendss_volt_var`: InvControl VOLTVAR with RefReactivePower=VARMAX, kvarMax = our limit L,
its XY curve our rule's curve scaled to L (y·Q_base/L; OpenDSS then clips at 1 = L, where
the limits bind), flat points added beyond the curve's ends (OpenDSS extrapolates XY
curves linearly), the PVSystem's kVA never binding.

`opendss_inverters`: the DER as `Unit`s with their own capability — kVA = S̄, Pmpp = P̄ at
irradiance P/P̄, kvarMax the capability's peak and %PminkvarMax the power where it peaks
(below it OpenDSS limits Q on the straight line kvarMax·P/P_peak: the power-factor limit),
WattPriority yes or no — under VOLTVAR, VOLTWATT (VoltwattYAxis=PMPPPU: the cap in p.u. of
Pmpp) or CombiMode=VV_VW.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import opendssdirect as dss

from opfbench.network import Network

FAR = (0.5, 1.5)  # p.u.: the flat points added beyond a curve's ends


@dataclass(frozen=True)
class DssAnswer:
    """OpenDSS's steady state: q_mvar, p_mw (n_der,), vm (n_bus,) p.u. in our bus order, line
    losses kW, whether the solution and its control loop converged, control iterations."""

    q_mvar: np.ndarray
    p_mw: np.ndarray
    vm: np.ndarray
    losses_kw: float
    converged: bool
    control_iterations: int


@dataclass(frozen=True)
class Unit:
    """One DER as an OpenDSS PVSystem: kVA rating, Pmpp (kW) and the power it has (kW, at
    irradiance p/Pmpp), kvarMax (kvar; kvarMaxAbs the same), %PminkvarMax (None: off)."""

    kva: float
    pmpp_kw: float
    p_kw: float
    kvar_max: float
    pct_pmin_kvar_max: float | None = None


def _num(value: float) -> str:
    return repr(float(value))


def _bus(net: Network, i: int) -> str:
    return f"b{int(net.bus_ids[i])}"


def _curve(name: str, x: Sequence[float], y: Sequence[float]) -> str:
    """An XY curve with flat points beyond its ends."""
    xs, ys = (FAR[0], *x, FAR[1]), (y[0], *y, y[-1])
    return f"new xycurve.{name} npts={len(xs)} xarray=[{' '.join(map(_num, xs))}] yarray=[{' '.join(map(_num, ys))}]"


def _circuit(net: Network, load_p_mw: np.ndarray, load_q_mvar: np.ndarray) -> float:
    """Clear OpenDSS and write the network and its loads; returns the base kV."""
    kv = float(net.base_kv[net.slack])
    z_base = kv**2 / net.base_mva
    dss.Basic.ClearAll()
    run = dss.Text.Command
    run("clear")
    run(f"new circuit.oracle basekv={kv} pu={net.v_slack} angle=0 phases=3 bus1={_bus(net, net.slack)} MVAsc3=1e10 MVAsc1=1e10")
    for k in np.flatnonzero(net.status):
        r, x = net.r[k] * z_base, net.x[k] * z_base
        run(
            f"new line.l{k} bus1={_bus(net, net.f[k])} bus2={_bus(net, net.t[k])} phases=3 length=1 units=none "
            f"r1={_num(r)} x1={_num(x)} r0={_num(r)} x0={_num(x)} c1=0 c0=0"
        )
    for i in np.flatnonzero((load_p_mw != 0) | (load_q_mvar != 0)):
        run(
            f"new load.d{i} bus1={_bus(net, i)} phases=3 kv={kv} kw={_num(load_p_mw[i] * 1e3)} kvar={_num(load_q_mvar[i] * 1e3)} "
            "model=1 vminpu=0.05 vmaxpu=2 vlowpu=0.01"
        )
    return kv


def _pv(net: Network, d: int, kv: float, unit: Unit, watt_priority: bool) -> str:
    ramp = "" if unit.pct_pmin_kvar_max is None else f" %PminkvarMax={_num(unit.pct_pmin_kvar_max)}"
    return (
        f"new pvsystem.pv{d} bus1={_bus(net, net.ders[d].bus)} phases=3 kv={kv} kva={_num(unit.kva)} "
        f"pmpp={_num(unit.pmpp_kw)} irradiance={_num(unit.p_kw / unit.pmpp_kw)} %cutin=0 %cutout=0 "
        f"kvarmax={_num(unit.kvar_max)} kvarmaxabs={_num(unit.kvar_max)}{ramp} "
        f"wattpriority={'yes' if watt_priority else 'no'} pfpriority=no varfollowinverter=no vminpu=0.05 vmaxpu=2"
    )


def _solve(net: Network) -> DssAnswer:
    run = dss.Text.Command
    run("calcv")
    run("set mode=snapshot controlmode=static maxcontroliter=5000 maxiterations=100 tolerance=1e-12")
    dss.Solution.Solve()
    q, p = np.zeros(len(net.ders)), np.zeros(len(net.ders))
    for d in range(len(net.ders)):
        dss.Circuit.SetActiveElement(f"pvsystem.pv{d}")
        powers = np.asarray(dss.CktElement.Powers())  # kW, kvar per conductor, positive = into the element
        p[d], q[d] = -powers[0:6:2].sum() / 1e3, -powers[1:6:2].sum() / 1e3
    names = [n.lower() for n in dss.Circuit.AllBusNames()]
    mags = np.asarray(dss.Circuit.AllBusMagPu()).reshape(len(names), 3).mean(axis=1)
    by_name = dict(zip(names, mags, strict=True))
    vm = np.array([by_name[_bus(net, i)] for i in range(net.n_bus)])
    losses = float(dss.Circuit.LineLosses()[0])  # kW
    return DssAnswer(q, p, vm, losses, bool(dss.Solution.Converged()), int(dss.Solution.ControlIterations()))


TIGHT = "varchangetolerance=1e-10 voltagechangetolerance=1e-10 activepchangetolerance=1e-10 eventlog=no"


def opendss_volt_var(
    net: Network,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    der_p_mw: np.ndarray,
    limit_mvar: np.ndarray,
    curve_v: tuple[float, ...],
    curve_q: tuple[float, ...],
    q_base_mva: np.ndarray,
) -> DssAnswer:
    """The Volt-VAR steady state of one snapshot: bus loads (n_bus,) MW/MVAr, DER P (n_der,)
    MW, limits L (n_der,) MVAr > 0, the curve (|V| p.u. → Q in p.u. of `q_base_mva`)."""
    kv = _circuit(net, load_p_mw, load_q_mvar)
    run = dss.Text.Command
    for d in range(len(net.ders)):
        p_kw, l_kvar = der_p_mw[d] * 1e3, limit_mvar[d] * 1e3
        run(_curve(f"vv{d}", curve_v, np.array(curve_q) * q_base_mva[d] / limit_mvar[d]))
        run(_pv(net, d, kv, Unit(10 * (p_kw + l_kvar), p_kw, p_kw, l_kvar), watt_priority=False))
        run(
            f"new invcontrol.ic{d} derlist=[pvsystem.pv{d}] mode=voltvar vvc_curve1=vv{d} voltage_curvex_ref=rated "
            f"refreactivepower=varmax deltaq_factor=-1 {TIGHT}"
        )
    run(f"set voltagebases=[{kv}]")
    return _solve(net)


def opendss_inverters(
    net: Network,
    load_p_mw: np.ndarray,
    load_q_mvar: np.ndarray,
    units: Sequence[Unit],
    volt_var: tuple[tuple[float, ...], tuple[float, ...]] | None,
    volt_watt: tuple[tuple[float, ...], tuple[float, ...]] | None,
    q_base_mva: np.ndarray,
    watt_priority: bool = True,
) -> DssAnswer:
    """The steady state of one snapshot under Volt-VAR (curve |V| → Q in p.u. of
    `q_base_mva`), Volt-Watt (curve |V| → P cap in p.u. of Pmpp) or both (VV_VW), the DER
    as `units`, with watt or var priority."""
    kv = _circuit(net, load_p_mw, load_q_mvar)
    run = dss.Text.Command
    for d, unit in enumerate(units):
        curves = []
        if volt_var is not None:
            run(_curve(f"vv{d}", volt_var[0], np.array(volt_var[1]) * q_base_mva[d] * 1e3 / unit.kvar_max))
            curves.append(f"vvc_curve1=vv{d} refreactivepower=varmax deltaq_factor=-1")
        if volt_watt is not None:
            run(_curve(f"vw{d}", *volt_watt))
            curves.append(f"voltwatt_curve=vw{d} voltwattyaxis=pmpppu deltap_factor=-1")
        mode = "combimode=vv_vw" if len(curves) == 2 else "mode=voltvar" if volt_var is not None else "mode=voltwatt"
        run(_pv(net, d, kv, unit, watt_priority))
        run(f"new invcontrol.ic{d} derlist=[pvsystem.pv{d}] {mode} {' '.join(curves)} voltage_curvex_ref=rated {TIGHT}")
    run(f"set voltagebases=[{kv}]")
    return _solve(net)
