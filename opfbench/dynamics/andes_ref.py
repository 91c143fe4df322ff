"""Cross-check against ANDES (PyPI; a test-time dependency like pandapower): the same
network, source, constant-impedance loads, ANDES's third-order motor (Motor3) and
REGCA1 converters with fixed current commands, on a mild fault where ANDES converges
unmodified. Our model runs with `InverterParams(control="constant-current")`.

ANDES pitfalls handled here (each one moved results before it was):
- Line.Sn defaults to 100 MVA: set it to the case base, or impedances are 10× off.
- Motor3 torque coefficients are not converted to the system base: scale by Sn/Sb.
  Our Tm = Te0·((1 − s)/(1 − s0))² = A·(1 − s)² is Motor3's aa + bb·s + c2·s² with
  c1 = −A/2, c2 = A, c3 = A/2.
- Motor3's power-flow start (slip 1) diverges for small motors: seed slip, E', I and
  torques from the equivalent circuit.
- REGCA1's low-voltage active-current gain and power logic (LVG, LVPL) are disabled so
  the converter is the constant-current source of our model (20-ms lag Tg).
"""

from __future__ import annotations

import importlib.util
import logging
from dataclasses import replace

import numpy as np

from opfbench.dynamics.params import FaultParams, InverterParams, ModelParams
from opfbench.dynamics.rms_model import DynamicModel, build_model
from opfbench.dynamics.simulate import recovery_ms, simulate
from opfbench.timing import elapsed_ms, now

MILD_FAULT = FaultParams(bus=27, impedance_pu=0.3, t_end_s=1.0)
CROSS_CHECK_PARAMS = replace(ModelParams(), inverters=InverterParams(control="constant-current"))


def andes_available() -> bool:
    return importlib.util.find_spec("andes") is not None


def _dq(c: complex | np.ndarray) -> tuple:
    """ANDES's (d, q) components of a phasor c: vd = −Im c, vq = Re c."""
    return -np.imag(c), np.real(c)


def andes_system(model: DynamicModel, fault: FaultParams):
    """The ANDES system of `model` with `fault`, set up, power flow not yet run."""
    import andes

    andes.config_logger(stream_level=logging.ERROR)
    net = model.net
    ss = andes.System(default_config=True)
    sb = ss.config.mva
    base = net.base_mva
    vn = float(net.base_kv[net.slack])
    ids = [int(b) for b in net.bus_ids]
    src_bus = max(ids) + 1
    for i, b in enumerate(ids):
        ss.add(
            "Bus",
            {
                "idx": b,
                "name": f"B{b}",
                "Vn": float(net.base_kv[i]),
                "v0": float(abs(model.v0[i])),
                "a0": float(np.angle(model.v0[i])),
            },
        )
    ss.add("Bus", {"idx": src_bus, "name": "EMF", "Vn": vn, "v0": abs(model.emf), "a0": float(np.angle(model.emf))})
    ss.add(
        "Slack",
        {
            "idx": "source",
            "bus": src_bus,
            "Vn": vn,
            "Sn": sb,
            "v0": abs(model.emf),
            "a0": float(np.angle(model.emf)),
            "p0": 0.0,
            "q0": 0.0,
            "vmax": 2.0,
            "vmin": 0.0,
        },
    )
    for k in np.flatnonzero(net.status):
        ss.add(
            "Line",
            {
                "idx": f"L{k}",
                "bus1": ids[net.f[k]],
                "bus2": ids[net.t[k]],
                "Sn": base,
                "Vn1": vn,
                "Vn2": vn,
                "r": float(net.r[k]),
                "x": float(net.x[k]),
                "b": float(net.b[k]),
                "tap": float(net.tap[k]),
                "phi": float(np.deg2rad(net.shift[k])),
            },
        )
    ss.add(
        "Line",
        {
            "idx": "Lsource",
            "bus1": src_bus,
            "bus2": ids[net.slack],
            "Sn": base,
            "Vn1": vn,
            "Vn2": vn,
            "r": model.params.source.resistance_pu,
            "x": model.params.source.impedance_pu,
        },
    )

    # static loads: what is left of the model's diagonal after the network and motors
    y_static = np.diag(model.y - net.ybus).copy()
    y_static[net.slack] -= 1.0 / model.params.source.z_pu
    y_static[model.mot_bus] -= model.mot_y
    s_static = np.conj(y_static) * np.abs(model.v0) ** 2 * base  # MVA consumed
    for i in np.flatnonzero(np.abs(s_static) > 1e-12).tolist():
        ss.add(
            "PQ",
            {
                "idx": f"P{ids[i]}",
                "bus": ids[i],
                "Vn": vn,
                "p0": float(s_static[i].real / sb),
                "q0": float(s_static[i].imag / sb),
                "vmin": 0.05,
                "vmax": 2.0,
            },
        )

    mp = model.params.motors
    for m, i in enumerate(model.mot_bus):
        par = model.mot_par[m]
        s_mva = float(np.real(model.mot_y[m] * (mp.rs + 1j * mp.xp)) * base)  # motor MVA base
        a_coef = par[5] / (1.0 - par[6]) ** 2 * s_mva / sb
        ss.add(
            "Motor3",
            {
                "idx": f"M{ids[i]}",
                "bus": ids[i],
                "Sn": s_mva,
                "Vn": vn,
                "fn": 50.0,
                "rs": mp.rs,
                "xs": mp.xs,
                "rr1": mp.rr,
                "xr1": mp.xr,
                "xm": mp.xm,
                "Hm": mp.h_s,
                "c1": -a_coef / 2,
                "c2": a_coef,
                "c3": a_coef / 2,
            },
        )

    nm = model.n_motors
    for d, i in enumerate(model.inv_bus):
        p0, q0 = model.inv_par[d, 1] * base, model.inv_par[d, 2] * base
        ss.add(
            "PV",
            {
                "idx": f"G{ids[i]}",
                "bus": ids[i],
                "Vn": vn,
                "Sn": base,
                "p0": p0 / sb,
                "q0": q0 / sb,
                "v0": float(abs(model.v0[i])),
                "qmax": 99.0,
                "qmin": -99.0,
                "pmax": 99.0,
                "pmin": -99.0,
            },
        )
        ss.add(
            "REGCA1",
            {
                "idx": f"R{ids[i]}",
                "bus": ids[i],
                "gen": f"G{ids[i]}",
                "Sn": base,
                "Tg": model.params.inverters.t_lag_s,
                "Lvplsw": 0,
                "Lvpnt0": 0.001,
                "Lvpnt1": 0.002,
                "Rrpwr": 999.0,
                "Iqrmax": 999.0,
                "Iqrmin": -999.0,
                "Volim": 9.0,
                "Iolim": -9.0,
            },
        )
    ss.add(
        "Fault",
        {
            "idx": "F1",
            "bus": fault.bus,
            "tf": fault.t_on_s,
            "tc": fault.t_on_s + fault.duration_s,
            "xf": fault.impedance_pu * sb / base,
            "rf": 0.0,
        },
    )
    ss.setup()
    ss.PQ.config.pq2z = 0
    _seed_motors(ss, model, nm)
    return ss


def _seed_motors(ss, model: DynamicModel, nm: int) -> None:
    """Start Motor3's power flow from the equivalent-circuit solution (else it diverges)."""
    pf = ss.PFlow
    original = pf.init
    base, sb = model.net.base_mva, ss.config.mva
    e = model.x0[:nm] + 1j * model.x0[nm : 2 * nm]
    v = model.v0[model.mot_bus]
    i_sys = (v - e) * model.mot_y * base / sb  # motor current on the ANDES base
    te = np.real(e * np.conj(i_sys))

    def init():
        out = original()
        mot = ss.Motor3
        mot.slip.v[:] = model.x0[2 * nm : 3 * nm]
        mot.e1d.v[:], mot.e1q.v[:] = _dq(e)
        mot.vd.v[:], mot.vq.v[:] = _dq(v)
        mot.Id.v[:], mot.Iq.v[:] = _dq(i_sys)
        mot.te.v[:] = te
        mot.tm.v[:] = te
        mot.p.v[:] = np.real(v * np.conj(i_sys))
        mot.q.v[:] = np.imag(v * np.conj(i_sys))
        return out

    pf.init = init


def run_andes(model: DynamicModel, fault: FaultParams) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """(t, |V| (K, n) in the model's bus order, wall ms of the time-domain run, converged)."""
    ss = andes_system(model, fault)
    ok = ss.PFlow.run()
    if not ok:
        return np.zeros(0), np.zeros((0, model.net.n_bus)), float("nan"), False
    ss.TDS.config.tf = fault.t_end_s
    ss.TDS.config.tstep = fault.step_s
    ss.TDS.config.fixt = 1
    ss.TDS.config.shrinkt = 0
    ss.TDS.config.no_tqdm = 1
    start = now()
    ss.TDS.run()
    ms = elapsed_ms(start)
    t = np.asarray(ss.dae.ts.t)
    addr = ss.Bus.v.a[: model.net.n_bus]
    vm = np.asarray(ss.dae.ts.y)[:, addr]
    return t, vm, ms, bool(ss.TDS.converged) if hasattr(ss.TDS, "converged") else bool(ss.exit_code == 0)


def mild_fault_comparison(fault: FaultParams = MILD_FAULT) -> dict:
    """Ours vs ANDES on the paper feeder at the reference operating point with LFMA (k = 0)
    setpoints: recovery times per bus, max |ΔV|, wall times."""
    from opfbench.io import load_network
    from opfbench.registry.catalog import run_strategy
    from opfbench.scenario import Scenario

    net = load_network("paper33")
    sc = Scenario.snapshot(net)
    model = build_model(sc, run_strategy("lfma", sc, 0.0).q_mvar[0], CROSS_CHECK_PARAMS)
    ours = simulate(model, fault)
    t, vm, ms, ok = run_andes(model, fault)
    rec_ours = ours.recovery_ms()
    rec_andes = recovery_ms(t, vm, fault.t_on_s, ok) if ok else np.full(net.n_bus, np.nan)
    v_interp = np.column_stack([np.interp(ours.t, t, vm[:, b]) for b in range(net.n_bus)]) if ok else None
    return {
        "andes_ok": ok,
        "andes_sim_ms": ms,
        "sim_ms": ours.sim_ms,
        "recovery_ms": rec_ours,
        "andes_recovery_ms": rec_andes,
        "fault_bus_vmin": float(ours.vmin()[model.net.index_of(fault.bus)]),
        "max_dv_pu": None if v_interp is None else float(np.abs(v_interp - ours.vm).max()),
        "t": ours.t,
        "vm": ours.vm,
        "andes_t": t,
        "andes_vm": vm,
    }
