"""Steady state of the third-order induction motor (Kundur §7.2.3, the equivalent
circuit Rs + jXs + jXm ∥ (Rr/s + jXr)), used to start the motors at the pre-fault
operating point: the slip that draws the motor's share of P, its Q, E' and torque."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from opfbench.dynamics.params import MotorParams
from opfbench.errors import InputError


def impedance(p: MotorParams, s: float | np.ndarray) -> complex | np.ndarray:
    """Equivalent-circuit input impedance at slip s (motor base)."""
    rotor = p.rr / s + 1j * p.xr
    return p.rs + 1j * p.xs + (1j * p.xm * rotor) / (1j * p.xm + rotor)


def _power_at_unit_voltage(p: MotorParams, s: float) -> float:
    """Electrical P drawn at |V| = 1 (motor base)."""
    return float((1.0 / np.conj(impedance(p, s))).real)


def _airgap_torque_at_unit_voltage(p: MotorParams, s: float) -> float:
    i = 1.0 / impedance(p, s)
    return float(_power_at_unit_voltage(p, s) - p.rs * np.abs(i) ** 2)


@lru_cache(maxsize=32)
def peak_slips(p: MotorParams) -> tuple[float, float]:
    """(slip of maximum electrical P, breakdown slip of maximum air-gap torque) — both
    independent of the voltage, since P and torque scale with |V|²."""
    s_p = minimize_scalar(
        lambda s: -_power_at_unit_voltage(p, s), bounds=(1e-5, 1.0), method="bounded", options={"xatol": 1e-12}
    ).x
    s_t = minimize_scalar(
        lambda s: -_airgap_torque_at_unit_voltage(p, s), bounds=(1e-5, 1.0), method="bounded", options={"xatol": 1e-12}
    ).x
    return float(s_p), float(s_t)


@dataclass(frozen=True)
class MotorState:
    """Pre-fault state of one motor (motor base): slip, stator current I (into the
    motor), transient EMF E', electrical torque Te, and Q drawn in MVAr."""

    slip: float
    current: complex
    emf: complex
    torque: float
    q_mvar: float


def steady_state(p: MotorParams, v: complex, p_mw: float, bus_label: object) -> MotorState:
    """The motor of `p_mw` MW (MVA base p_mw / loading) at terminal voltage v (p.u.)."""
    s_base = p_mw / p.loading
    target = p.loading / abs(v) ** 2  # P at unit voltage that gives `loading` at |v|
    s_peak, _ = peak_slips(p)
    if _power_at_unit_voltage(p, s_peak) < target:
        raise InputError(
            f"bus {bus_label}: the motor cannot carry {p.loading:g} p.u. at the pre-fault "
            f"voltage {abs(v):.4f} p.u. (beyond its pull-out power)"
        )
    s0 = brentq(lambda s: _power_at_unit_voltage(p, s) - target, 1e-12, s_peak, xtol=1e-15, rtol=1e-15)
    i0 = v / impedance(p, s0)
    e0 = v - (p.rs + 1j * p.xp) * i0
    q = float((v * np.conj(i0)).imag) * s_base
    return MotorState(float(s0), complex(i0), complex(e0), float((e0 * np.conj(i0)).real), q)
