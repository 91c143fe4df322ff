"""Inverter references: the Danish LVRT reactive current, the current limit and the
reactive priority, at imposed voltages; and in the time domain the 20-ms lag reaches them."""

import numpy as np
import pytest

from opfbench.dynamics import kernel
from opfbench.dynamics.params import InverterParams


def _scalars(p: InverterParams) -> np.ndarray:
    sc = np.zeros(kernel.N_SCALARS)
    sc[kernel.S_IMAX], sc[kernel.S_SLOPE], sc[kernel.S_VDIP], sc[kernel.S_GCMAX] = p.i_max, p.slope, p.v_dip, p.gc_max
    sc[kernel.S_TF], sc[kernel.S_TLAG] = p.t_filter_s, p.t_lag_s
    return sc


def _curve(v: float) -> float:
    """Paper Fig. 1: 0 at 0.9 p.u., 100 % of rated current at 0.5 p.u. and below."""
    return 0.0 if v >= 0.9 else (1.0 if v <= 0.5 else (0.9 - v) / 0.4)


@pytest.mark.parametrize("v", [0.95, 0.8, 0.5, 0.3, 0.1])
@pytest.mark.parametrize("q0_pu", [0.0, 0.3, 0.6, -0.3])
def test_reactive_current_follows_the_curve_with_limit_and_priority(v, q0_pu):
    p = InverterParams()
    irat, p0 = 0.06, 0.048  # 0.6 MVA on a 10 MVA base, P at 0.8 × rating
    v0 = 1.0
    inv = np.array([[irat, p0, q0_pu * irat, q0_pu * irat / v0, p0 / v0]])
    idr, iqr = kernel.references(v, v, 1.0, inv, _scalars(p), np.zeros(1, dtype=np.bool_), 0)
    if v >= 0.9:
        iq_expected = q0_pu * irat / v
    else:
        iq_expected = q0_pu * irat + _curve(v) * irat
    iq_expected = float(np.clip(iq_expected, -1.1 * irat, 1.1 * irat))
    assert iqr == pytest.approx(iq_expected, rel=0.01, abs=1e-12)
    id_expected = min(p0 / v, np.sqrt((1.1 * irat) ** 2 - iq_expected**2))
    assert idr == pytest.approx(id_expected, rel=0.01, abs=1e-12)
    assert np.hypot(idr, iqr) <= 1.1 * irat * (1 + 1e-12)
    if v <= 0.5 and q0_pu >= 0.1:
        assert iqr == pytest.approx(1.1 * irat)  # the limit binds and Q has priority: no active current
        assert idr == pytest.approx(0.0, abs=1e-12)


def test_lags_reach_the_references():
    """Vf follows |V| through 10 ms, the currents their references through 20 ms: after
    0.2 s at an imposed 0.5 p.u. the injected Q is the grid code's full current."""
    p = InverterParams()
    sc = _scalars(p)
    inv = np.array([[0.06, 0.048, 0.0, 0.0, 0.048]])
    x = np.array([1.0, 0.048, 0.0, 1.0])  # Vf, Id, Iq, r (no motors)
    v = np.array([0.5 + 0j])
    dx = np.empty(4)
    h = 1e-4
    for _ in range(2000):
        kernel.derivatives(
            x,
            v,
            np.zeros(0, np.int64),
            np.zeros((0, kernel.N_MOTOR_COLUMNS)),
            np.zeros(1, np.int64),
            inv,
            sc,
            np.zeros(1, dtype=np.bool_),
            dx,
        )
        x = x + h * dx
    assert x[0] == pytest.approx(0.5, abs=1e-6)
    assert x[2] * 0.5 == pytest.approx(0.5 * 0.06, rel=0.01)  # Q = |V|·Iq, 100 % rated current
