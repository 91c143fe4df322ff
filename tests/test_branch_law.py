"""The load law over a row of snapshots (`multiphase.branches.drawn_row`): a
constant-power branch's vectorized pass (in band and above vmaxpu) must give what the
scalar law `drawn` gives at every voltage — across vlowpu, vminpu and vmaxpu — and every
other law is `drawn` itself."""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_PQ, CONSTANT_Z, EXPONENTIAL, LoadModels, drawn, drawn_row


@pytest.mark.parametrize("model", [CONSTANT_PQ, CONSTANT_Z, EXPONENTIAL, CONSTANT_I])
def test_a_row_is_the_scalar_law_at_every_voltage(model):
    law = LoadModels(np.array([model]), np.array([0.92]), np.array([1.05]), np.array([0.5]), np.array([0.8]), np.array([2.5]))
    law = law.branch_law(np.array([0]))
    constants = [float(c[0]) if c.dtype != bool else bool(c[0]) for c in law.constants]
    vbase = 230.0
    u = np.concatenate([np.linspace(0.0, 1.3, 1301), [0.5, 0.92, 1.05, np.nan]])
    v = u * vbase * np.exp(1j * np.linspace(-0.6, 0.4, u.size))
    rng = np.random.default_rng(3)
    p, q = rng.uniform(0, 5e3, u.size), rng.uniform(-2e3, 2e3, u.size)
    row = np.empty(u.size, dtype=complex)
    drawn_row(v, p, q, vbase, *constants, row)
    scalar = np.array([drawn(v[s], p[s], q[s], vbase, *constants) for s in range(u.size)])
    np.testing.assert_allclose(row, scalar, rtol=1e-13, atol=1e-300, equal_nan=True)
    assert (np.abs(row[1:-1]) > 0).all()  # every non-zero voltage draws a current
