"""The dynamic model of one operating point: the network with its upstream source,
static loads, induction motors and inverters, started from the AC power flow at the
strategy's setpoints (all state derivatives zero at t = 0).

Per unit on the case's MVA base; voltages in p.u. of the bus base kV. The static part of
each load is a constant impedance at its pre-fault value, P_static = (1 − share)·P,
Q_static = Q − Q_motor, so the total load (and the power flow) is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.capability import qmax
from opfbench.dynamics import kernel
from opfbench.dynamics.motor import peak_slips, steady_state
from opfbench.dynamics.params import NOMINAL_HZ, ModelParams
from opfbench.errors import InputError, NetworkError
from opfbench.network import Network
from opfbench.powerflow import solve_pf
from opfbench.scenario import Scenario

PF_TOLERANCE = 1e-12  # p.u. mismatch: the start must be steady to 1e-8 in dVf/dt = (|V| − Vf)/10 ms
STEADY_TOLERANCE = 1e-6  # largest |dx/dt| at t = 0 accepted as a steady start


@dataclass(frozen=True, eq=False)
class DynamicModel:
    """Arrays the kernel runs on, plus what the study reports.

    v0 (n,) complex pre-fault voltages; emf the source EMF (p.u., complex); y (n, n)
    admittance matrix of the network with source, static loads and motor Norton
    admittances; i_const (n,) constant current injections (source Norton current, fixed
    generators); motor and inverter tables as `kernel` documents; x0 the initial state."""

    net: Network
    params: ModelParams
    v0: np.ndarray
    emf: complex
    y: np.ndarray
    i_const: np.ndarray
    mot_bus: np.ndarray
    mot_y: np.ndarray
    mot_par: np.ndarray
    inv_bus: np.ndarray
    inv_par: np.ndarray
    scalars: np.ndarray
    x0: np.ndarray
    breakdown_slip: float

    @property
    def n_motors(self) -> int:
        return len(self.mot_bus)

    @property
    def n_ders(self) -> int:
        return len(self.inv_bus)

    def impedance(self, fault_bus: int | None = None, fault_impedance_pu: float = 0.0) -> np.ndarray:
        """Z = Y⁻¹, with a shunt reactance j·fault_impedance_pu at internal bus `fault_bus`."""
        y = self.y.copy()
        if fault_bus is not None:
            y[fault_bus, fault_bus] += 1.0 / (1j * max(fault_impedance_pu, 1e-9))
        return np.linalg.inv(y)

    def voltages(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Bus voltages (complex p.u.) at state x on the network with impedance matrix z."""
        v_der = self.v0[self.inv_bus].copy()
        v, ok = kernel.network_voltages(
            x,
            np.ascontiguousarray(z.real),
            np.ascontiguousarray(z.imag),
            self.i_const,
            self.mot_bus,
            self.mot_y,
            self.inv_bus,
            np.zeros(self.n_ders, dtype=np.bool_),
            v_der,
        )
        if not ok:
            raise NetworkError("network solve did not converge")
        return v

    def derivatives(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """dx/dt at state x on the network with impedance matrix z."""
        v_der = self.v0[self.inv_bus].copy()
        dx, _, _ = kernel.rhs(
            x,
            np.ascontiguousarray(z.real),
            np.ascontiguousarray(z.imag),
            self.i_const,
            self.mot_bus,
            self.mot_y,
            self.mot_par,
            self.inv_bus,
            self.inv_par,
            self.scalars,
            np.zeros(self.n_ders, dtype=np.bool_),
            v_der,
        )
        return dx

    def der_q_mvar(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Reactive output of each DER (MVAr) at state x, voltages v."""
        nm, nd = self.n_motors, self.n_ders
        return np.abs(v[self.inv_bus]) * x[3 * nm + 2 * nd : 3 * nm + 3 * nd] * self.net.base_mva


def source_emf(net: Network, v: np.ndarray, s_slack_mva: complex, z_source: complex) -> complex:
    """EMF behind the source impedance that delivers the slack's power at voltage v[slack]."""
    i = np.conj(s_slack_mva / net.base_mva / v[net.slack])
    return complex(v[net.slack] + z_source * i)


def with_source_bus(net: Network, z_source: complex, emf_pu: float) -> Network:
    """The network with the source's EMF node as a new slack bus (|V| = emf_pu) behind
    z_source; the old slack becomes a load bus. The new bus is the last index."""
    n = net.n_bus
    bus_type = np.append(net.bus_type, 3)
    bus_type[net.slack] = 1

    def add(arr: np.ndarray, value: float) -> np.ndarray:
        return np.append(arr, value)

    return net.with_changes(
        name=f"{net.name}+source",
        bus_ids=add(net.bus_ids, int(net.bus_ids.max()) + 1),
        bus_type=bus_type,
        base_kv=add(net.base_kv, net.base_kv[net.slack]),
        load_p_mw=add(net.load_p_mw, 0.0),
        load_q_mvar=add(net.load_q_mvar, 0.0),
        gs_mw=add(net.gs_mw, 0.0),
        bs_mvar=add(net.bs_mvar, 0.0),
        vmin=add(net.vmin, 0.0),
        vmax=add(net.vmax, 2.0),
        f=add(net.f, n),
        t=add(net.t, net.slack),
        r=add(net.r, z_source.real),
        x=add(net.x, z_source.imag),
        b=add(net.b, 0.0),
        tap=add(net.tap, 1.0),
        shift=add(net.shift, 0.0),
        status=np.append(net.status, True),
        slack=n,
        v_slack=float(emf_pu),
    )


def check_modelled(net: Network) -> None:
    """Refuse what the dynamic model does not model: voltage-controlled (PV) buses — their
    generators would need a voltage regulator and machine model; it holds every generator
    at a fixed current."""
    if net.pv_buses.size:
        ids = ", ".join(str(b) for b in net.bus_ids[net.pv_buses])
        raise NetworkError(
            f"{net.name}: the fault model does not model voltage-controlled (PV) buses ({ids}); "
            "make them PQ buses (type 1) with fixed P and Q"
        )


def prefault_flow(
    scenario: Scenario, q_mvar: np.ndarray, params: ModelParams, emf_pu: float | None = None
) -> tuple[np.ndarray, complex]:
    """(V (n,) complex, E) of the pre-fault AC power flow at DER setpoints q_mvar (n_der,).
    emf_pu None: the slack at its scheduled voltage and E re-set to match ("reset");
    otherwise the source EMF |E| = emf_pu is the slack of the power flow."""
    net = scenario.net
    s = scenario.injections(np.asarray(q_mvar, float)[None, :])[0]
    z_src = params.source.z_pu
    if emf_pu is None:
        pf = solve_pf(net, s, tol=PF_TOLERANCE)
        if not pf.converged:
            raise NetworkError(f"{net.name}: the pre-fault power flow did not converge")
        return pf.v, source_emf(net, pf.v, complex(pf.slack_s_mva), z_src)
    ext = with_source_bus(net, z_src, emf_pu)
    pf = solve_pf(ext, np.append(s, 0.0), tol=PF_TOLERANCE)
    if not pf.converged:
        raise NetworkError(f"{net.name}: the pre-fault power flow behind the source EMF {emf_pu} p.u. did not converge")
    return pf.v[:-1], complex(pf.v[-1])


def build_model(
    scenario: Scenario, q_mvar: np.ndarray, params: ModelParams, emf_pu: float | None = None, row: int = 0
) -> DynamicModel:
    """The dynamic model at snapshot `row` of `scenario` with DER reactive setpoints
    q_mvar (n_der,) MVAr; `emf_pu` as `prefault_flow`."""
    scenario = scenario.take(slice(row, row + 1))
    net = scenario.net
    base = net.base_mva
    v0, emf = prefault_flow(scenario, q_mvar, params, emf_pu)
    mp, ip = params.motors, params.inverters
    load = scenario.bus_load_mva()[0]

    y = np.array(net.ybus, dtype=complex)
    z_src = params.source.z_pu
    y[net.slack, net.slack] += 1.0 / z_src
    i_const = np.zeros(net.n_bus, dtype=complex)
    i_const[net.slack] += emf / z_src
    gen = np.zeros(net.n_bus, dtype=complex)
    np.add.at(gen, net.gen_bus, (net.gen_p_mw + 1j * net.gen_q_mvar) / base)
    i_const += np.conj(gen / v0)  # fixed generators: constant current at their pre-fault value

    mot_bus, mot_y, mot_rows, emfs, slips = [], [], [], [], []
    static = load.copy()
    for i in np.flatnonzero((load.real > 0) & (mp.share > 0)):
        p_m = mp.share * load.real[i]
        st = steady_state(mp, complex(v0[i]), p_m, net.bus_ids[i])
        ratio = p_m / mp.loading / base  # motor MVA base / system base
        static[i] -= p_m + 1j * st.q_mvar
        yn = ratio / (mp.rs + 1j * mp.xp)
        y[i, i] += yn
        mot_bus.append(i)
        mot_y.append(yn)
        emfs.append(st.emf)
        slips.append(st.slip)
        g = 1.0 / (mp.rs + 1j * mp.xp)
        mot_rows.append(
            [
                mp.rs,
                mp.xp,
                mp.x0 - mp.xp,
                mp.t0p_s,
                mp.h_s,
                st.torque,
                st.slip,
                2.0 if mp.torque == "quadratic" else 0.0,
                g.real,
                g.imag,
            ]
        )
    y[np.diag_indices(net.n_bus)] += np.conj(static / base) / np.abs(v0) ** 2

    der_p = scenario.der_p_mw[0]
    rating = net.der_rating_mw
    is_dfig = np.array([k == "DFIG" for k in net.der_kinds], dtype=bool)  # inverters: their nameplate S̄
    s_rated = np.where(is_dfig, np.hypot(der_p, qmax(net.der_kinds, der_p, rating)), net.der_s_mva)
    vd = np.abs(v0[net.der_bus])
    p0, q0 = der_p / base, np.asarray(q_mvar, float) / base
    inv_par = (
        np.column_stack([s_rated / base, p0, q0, q0 / vd, p0 / vd]) if len(net.ders) else np.zeros((0, kernel.N_INVERTER_COLUMNS))
    )
    sc = np.zeros(kernel.N_SCALARS)
    sc[
        [
            kernel.S_WB,
            kernel.S_IMAX,
            kernel.S_SLOPE,
            kernel.S_VDIP,
            kernel.S_GCMAX,
            kernel.S_TF,
            kernel.S_TLAG,
            kernel.S_RAMP,
            kernel.S_RAMP_RATE,
            kernel.S_TRIP,
            kernel.S_VTRIP,
            kernel.S_CC,
        ]
    ] = [
        2 * np.pi * NOMINAL_HZ,
        ip.i_max,
        ip.slope,
        ip.v_dip,
        ip.gc_max,
        ip.t_filter_s,
        ip.t_lag_s,
        1.0 if ip.active == "ramp" else 0.0,
        ip.ramp_pu_s,
        1.0 if ip.area_c_trip else 0.0,
        ip.v_trip,
        1.0 if ip.control == "constant-current" else 0.0,
    ]
    low = np.flatnonzero(vd < ip.v_dip)
    if low.size:
        b = net.bus_ids[net.der_bus[low[0]]]
        raise InputError(
            f"{net.name}: DER bus {b} is at {vd[low[0]]:.4f} p.u. before the fault, below the grid "
            f"code's {ip.v_dip} p.u.: no steady pre-fault state"
        )
    over = np.hypot(p0, q0) / vd > ip.i_max * s_rated / base * (1 + 1e-9)
    if over.any():
        b = net.bus_ids[net.der_bus[np.flatnonzero(over)[0]]]
        raise InputError(
            f"{net.name}: the setpoint of the DER at bus {b} needs more than {ip.i_max} × its rated "
            "current before the fault: no steady pre-fault state"
        )
    e0 = np.array(emfs, dtype=complex)
    x0 = np.concatenate([e0.real, e0.imag, np.array(slips, float), vd, p0 / vd, q0 / vd, np.ones(len(vd))])
    return DynamicModel(
        net,
        params,
        v0,
        emf,
        y,
        i_const,
        np.array(mot_bus, dtype=np.int64),
        np.array(mot_y, dtype=complex),
        np.array(mot_rows, float).reshape(-1, kernel.N_MOTOR_COLUMNS),
        net.der_bus.astype(np.int64),
        np.ascontiguousarray(inv_par, dtype=float),
        sc,
        x0,
        peak_slips(mp)[1],
    )
