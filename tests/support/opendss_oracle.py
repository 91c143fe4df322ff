"""OpenDSS (through `opendssdirect.py`) as an independent, test-time-only oracle of the
closed-loop Volt-VAR steady state: our network as a balanced three-phase OpenDSS circuit
(a stiff source at the slack's voltage, lines from the branches' R and X in ohms, loads at
constant power with a low vminpu so they never turn to impedance), every DER a PVSystem at
its active power (constant power too: low vminpu), and an InvControl VOLTVAR per DER — RefReactivePower=VARMAX with
kvarMax = our limit L, its XY curve our rule's curve scaled to L (y·Q_base/L; OpenDSS then
clips at 1 = L, where the limits bind) with flat points added beyond the curve's ends
(OpenDSS extrapolates XY curves linearly), adaptive step factor (deltaQ_factor −1, as our
engine), tight VarChangeTolerance and VoltageChangeTolerance, a tight solution tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import opendssdirect as dss

from opfbench.network import Network

FAR = (0.5, 1.5)  # p.u.: the flat points added beyond a curve's ends


@dataclass(frozen=True)
class DssAnswer:
    """OpenDSS's steady state: q_mvar (n_der,), vm (n_bus,) p.u. in our bus order, line
    losses kW, whether the solution and its control loop converged, control iterations."""

    q_mvar: np.ndarray
    p_mw: np.ndarray
    vm: np.ndarray
    losses_kw: float
    converged: bool
    control_iterations: int


def _num(value: float) -> str:
    return repr(float(value))


def _bus(net: Network, i: int) -> str:
    return f"b{int(net.bus_ids[i])}"


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
    xs = (FAR[0], *curve_v, FAR[1])
    for d, der in enumerate(net.ders):
        p_kw, l_kvar = der_p_mw[d] * 1e3, limit_mvar[d] * 1e3
        ys = np.array((curve_q[0], *curve_q, curve_q[-1])) * q_base_mva[d] / limit_mvar[d]
        run(f"new xycurve.vv{d} npts={len(xs)} xarray=[{' '.join(map(_num, xs))}] yarray=[{' '.join(map(_num, ys))}]")
        run(
            f"new pvsystem.pv{d} bus1={_bus(net, der.bus)} phases=3 kv={kv} kva={_num(10 * (p_kw + l_kvar))} pmpp={_num(p_kw)} "
            f"irradiance=1 %cutin=0 %cutout=0 kvarmax={_num(l_kvar)} kvarmaxabs={_num(l_kvar)} wattpriority=no pfpriority=no "
            "varfollowinverter=no vminpu=0.05 vmaxpu=2"
        )
        run(
            f"new invcontrol.ic{d} derlist=[pvsystem.pv{d}] mode=voltvar vvc_curve1=vv{d} voltage_curvex_ref=rated "
            "refreactivepower=varmax deltaq_factor=-1 varchangetolerance=1e-10 voltagechangetolerance=1e-10 "
            "eventlog=no"
        )
    run(f"set voltagebases=[{kv}]")
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
