"""The compiled inner loop of the RMS simulation (numba): network solve, state
derivatives, fixed-step classical Runge–Kutta (RK4).

State vector x (real): motor E' real parts (nm), imaginary parts (nm), slips (nm);
inverter filtered voltage Vf (nd), active current Id (nd), reactive current Iq (nd),
active-power cap r (nd). Currents in p.u. on the system base, in the frame of the
terminal voltage: injected current I = (Id − j·Iq)·V/|V|, so P = |V|·Id and Q = |V|·Iq
(Q positive = injected).

The network: V = Z·(I_const + Σ y_m·E'_m + I_inv(V)), Z = (Y_bus + source + static
loads + motor Norton admittances [+ fault shunt])⁻¹. Only the inverter currents depend
on V (through its angle and magnitude), so a fixed-point iteration over the DER buses
converges in a few sweeps.

Motor (motor base, motor convention, Kundur §7.2.3 with stator transients neglected):
    V = E' + (Rs + jX')·I
    dE'/dt = −[E' − j(X0 − X')·I]/T0' − j·ω_s·s·E'
    2H·ds/dt = Tm(s) − Re(E'·conj(I)),  Tm = Tm0·((1 − s)/(1 − s0))^e  (e = 2 or 0)
"""

from __future__ import annotations

import numpy as np
from numba import njit

# columns of the motor parameter table
M_RS, M_XP, M_DX, M_T0, M_H, M_TM0, M_S0, M_EXP, M_GR, M_GI = range(10)
N_MOTOR_COLUMNS = 10  # M_GR + j·M_GI = 1/(Rs + jX'), motor base
# columns of the inverter parameter table
I_RAT, I_P0, I_Q0, I_IQ0, I_ID0 = range(5)
N_INVERTER_COLUMNS = 5
# inverter scalars
S_WB, S_IMAX, S_SLOPE, S_VDIP, S_GCMAX, S_TF, S_TLAG, S_RAMP, S_RAMP_RATE, S_TRIP, S_VTRIP, S_CC = range(12)
N_SCALARS = 12
FP_TOL = 1e-12  # p.u., fixed-point convergence of the DER-bus voltages
FP_MAX_ITER = 60


@njit(cache=True, fastmath=True)
def _matvec(zr, zi, ur, ui, outr, outi):
    """out = Z·u for Z = zr + j·zi, u = ur + j·ui, in real arithmetic (vectorizes; fastmath
    only here — the caller checks finiteness)."""
    n = zr.shape[0]
    for i in range(n):
        ar = 0.0
        ai = 0.0
        for j in range(n):
            ar += zr[i, j] * ur[j] - zi[i, j] * ui[j]
            ai += zr[i, j] * ui[j] + zi[i, j] * ur[j]
        outr[i] = ar
        outi[i] = ai


@njit(cache=True)
def _inverter_currents(x, v_der, tripped, nm, cur):
    nd = v_der.shape[0]
    off = 3 * nm
    for d in range(nd):
        mag = abs(v_der[d])
        if tripped[d] or mag < 1e-9:
            cur[d] = 0.0
        else:
            cur[d] = (x[off + nd + d] - 1j * x[off + 2 * nd + d]) * v_der[d] / mag


@njit(cache=True)
def network_voltages(x, zr, zi, i_const, mot_bus, mot_y, inv_bus, tripped, v_der):
    """All bus voltages for state x on the network Z = zr + j·zi. `v_der` (complex, nd)
    starts the fixed-point iteration and is overwritten with the solution.
    Returns (V, converged)."""
    nm = mot_bus.shape[0]
    nd = inv_bus.shape[0]
    n = i_const.shape[0]
    ur = i_const.real.copy()
    ui = i_const.imag.copy()
    for m in range(nm):
        c = mot_y[m] * (x[m] + 1j * x[nm + m])
        ur[mot_bus[m]] += c.real
        ui[mot_bus[m]] += c.imag
    vr = np.empty(n)
    vi = np.empty(n)
    _matvec(zr, zi, ur, ui, vr, vi)
    cur = np.empty(nd, dtype=np.complex128)
    ok = False
    for _ in range(FP_MAX_ITER):
        _inverter_currents(x, v_der, tripped, nm, cur)
        change = 0.0
        for d in range(nd):
            b = inv_bus[d]
            new = vr[b] + 1j * vi[b]
            for e in range(nd):
                new += (zr[b, inv_bus[e]] + 1j * zi[b, inv_bus[e]]) * cur[e]
            change = max(change, abs(new - v_der[d]))
            v_der[d] = new
        if change < FP_TOL:
            ok = True
            break
    _inverter_currents(x, v_der, tripped, nm, cur)
    v = vr + 1j * vi
    for e in range(nd):
        if cur[e] != 0.0:
            b = inv_bus[e]
            for i in range(n):
                v[i] += (zr[i, b] + 1j * zi[i, b]) * cur[e]
    return v, ok


@njit(cache=True)
def references(vm, vf, r, inv_par, sc, tripped, d):
    """(Id_ref, Iq_ref) of inverter d at terminal |V| = vm, filtered Vf = vf, cap r."""
    if tripped[d]:
        return 0.0, 0.0
    if sc[S_CC] > 0.5:  # constant-current control (no grid code): the pre-fault currents
        return inv_par[d, I_ID0], inv_par[d, I_IQ0]
    irat = inv_par[d, I_RAT]
    imax = sc[S_IMAX] * irat
    if vf < sc[S_VDIP]:
        base = inv_par[d, I_IQ0]  # pre-fault reactive current, held during the dip
        extra = min(sc[S_SLOPE] * (sc[S_VDIP] - vf), sc[S_GCMAX]) * irat
    else:
        base = inv_par[d, I_Q0] / max(vm, 1e-3)
        extra = 0.0
    iq = min(max(base + extra, -imax), imax)
    p = inv_par[d, I_P0] * (r if sc[S_RAMP] > 0.5 else 1.0)
    id_lim = np.sqrt(max(imax * imax - iq * iq, 0.0))
    idr = min(p / max(vm, 1e-3), id_lim)
    return idr, iq


@njit(cache=True)
def derivatives(x, v, mot_bus, mot_par, inv_bus, inv_par, sc, tripped, dx):
    """Fill dx with the state derivatives at state x and bus voltages v."""
    nm = mot_bus.shape[0]
    nd = inv_bus.shape[0]
    wb = sc[S_WB]
    for m in range(nm):
        e = x[m] + 1j * x[nm + m]
        s = x[2 * nm + m]
        i = (v[mot_bus[m]] - e) * (mot_par[m, M_GR] + 1j * mot_par[m, M_GI])
        de = -(e - 1j * mot_par[m, M_DX] * i) / mot_par[m, M_T0] - 1j * wb * s * e
        te = (e * np.conj(i)).real
        ratio = (1.0 - s) / (1.0 - mot_par[m, M_S0])
        tm = mot_par[m, M_TM0] * (ratio * ratio if mot_par[m, M_EXP] == 2.0 else 1.0)
        ds = (tm - te) / (2.0 * mot_par[m, M_H])
        if s >= 1.0 and ds > 0.0:
            ds = 0.0
        dx[m] = de.real
        dx[nm + m] = de.imag
        dx[2 * nm + m] = ds
    off = 3 * nm
    for d in range(nd):
        vm = abs(v[inv_bus[d]])
        vf = x[off + d]
        r = x[off + 3 * nd + d]
        idr, iqr = references(vm, vf, r, inv_par, sc, tripped, d)
        dx[off + d] = (vm - vf) / sc[S_TF]
        dx[off + nd + d] = (idr - x[off + nd + d]) / sc[S_TLAG]
        dx[off + 2 * nd + d] = (iqr - x[off + 2 * nd + d]) / sc[S_TLAG]
        if sc[S_RAMP] > 0.5:
            if vf < sc[S_VDIP]:
                dx[off + 3 * nd + d] = -r / sc[S_TLAG]
            elif r < 1.0:
                dx[off + 3 * nd + d] = sc[S_RAMP_RATE]
            else:
                dx[off + 3 * nd + d] = 0.0
        else:
            dx[off + 3 * nd + d] = 0.0


@njit(cache=True)
def rhs(x, zr, zi, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, tripped, v_der):
    """(dx/dt, V, converged) at state x on the network Z = zr + j·zi."""
    v, ok = network_voltages(x, zr, zi, i_const, mot_bus, mot_y, inv_bus, tripped, v_der)
    dx = np.empty_like(x)
    derivatives(x, v, mot_bus, mot_par, inv_bus, inv_par, sc, tripped, dx)
    return dx, v, ok


@njit(cache=True)
def integrate(x0, zrs, zis, seg_steps, seg_h, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, v_der0, every):
    """RK4 over consecutive segments; segment g uses the impedance matrix zrs[g] + j·zis[g], seg_steps[g]
    steps of seg_h[g] s. At a segment boundary the sample holds the voltages on the
    ending segment's network (just before the switch). Returns (t, vm, t_rec, vm_rec, q_rec, x_end, ok): |V| at
    every step (all buses), and every `every`-th step |V| and Q (p.u.) at the DER buses;
    ok False (arrays cut at the failing step) when the network solve or the states fail."""
    n = zrs.shape[1]
    nm = mot_bus.shape[0]
    nd = inv_bus.shape[0]
    off = 3 * nm
    total = 0
    for g in range(seg_steps.shape[0]):
        total += seg_steps[g]
    n_rec = total // every + 2
    t_rec = np.empty(n_rec)
    vm_rec = np.empty((n_rec, n))
    q_rec = np.empty((n_rec, nd))
    vm_all = np.empty((total + 1, n))
    t_all = np.empty(total + 1)
    tripped = np.zeros(nd, dtype=np.bool_)
    v_der = v_der0.copy()
    x = x0.copy()
    t = 0.0
    k = 0
    rec = 0
    ok = True
    for g in range(seg_steps.shape[0]):
        zr = zrs[g]
        zi = zis[g]
        h = seg_h[g]
        for step in range(seg_steps[g]):
            k1, v, ok1 = rhs(x, zr, zi, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, tripped, v_der)
            if step == 0 and g == 0:
                vm_all[0] = np.abs(v)
                t_all[0] = 0.0
                t_rec[0] = 0.0
                vm_rec[0] = vm_all[0]
                for d in range(nd):
                    q_rec[0, d] = abs(v[inv_bus[d]]) * x[off + 2 * nd + d]
                rec = 1
            k2, _, ok2 = rhs(x + 0.5 * h * k1, zr, zi, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, tripped, v_der)
            k3, _, ok3 = rhs(x + 0.5 * h * k2, zr, zi, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, tripped, v_der)
            k4, _, ok4 = rhs(x + h * k3, zr, zi, i_const, mot_bus, mot_y, mot_par, inv_bus, inv_par, sc, tripped, v_der)
            x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            for m in range(nm):
                if x[2 * nm + m] > 1.0:
                    x[2 * nm + m] = 1.0
            t += h
            k += 1
            # the state at t_k, voltages on this segment's network: at a switch instant the
            # sample is the one before the switch (as ANDES records it)
            v, ok5 = network_voltages(x, zr, zi, i_const, mot_bus, mot_y, inv_bus, tripped, v_der)
            if not (ok1 and ok2 and ok3 and ok4 and ok5) or not np.all(np.isfinite(x)):
                ok = False
                return t_all[:k], vm_all[:k], t_rec[:rec], vm_rec[:rec], q_rec[:rec], x, ok
            if sc[S_TRIP] > 0.5:
                for d in range(nd):
                    if abs(v[inv_bus[d]]) < sc[S_VTRIP]:
                        tripped[d] = True
            vm_all[k] = np.abs(v)
            t_all[k] = t
            if k % every == 0:
                t_rec[rec] = t
                vm_rec[rec] = vm_all[k]
                for d in range(nd):
                    q_rec[rec, d] = 0.0 if tripped[d] else abs(v[inv_bus[d]]) * x[off + 2 * nd + d]
                rec += 1
    return t_all, vm_all, t_rec[:rec], vm_rec[:rec], q_rec[:rec], x, ok
