"""The dynamic model starts in steady state at the AC power flow of each strategy's
setpoints, and stays there without a fault."""

from dataclasses import replace

import numpy as np
import pytest

from opfbench.dynamics.motor import impedance, steady_state
from opfbench.dynamics.params import FaultParams, ModelParams, MotorParams
from opfbench.dynamics.rms_model import build_model, prefault_flow
from opfbench.dynamics.simulate import simulate
from opfbench.io import load_network
from opfbench.powerflow import solve_pf
from opfbench.registry.catalog import run_strategy
from opfbench.scenario import Scenario

NET = load_network("paper33")
SCENARIO = Scenario.snapshot(NET)


def _setpoints(name: str, k: float = 0.0) -> np.ndarray:
    return run_strategy(name, SCENARIO, k).q_mvar[0]


@pytest.mark.parametrize("name", ["no-action", "llma", "lfma"])
@pytest.mark.parametrize("variant", ["reference", "emf=held", "source=0.1,motors=0.7"])
def test_start_is_steady_at_the_power_flow(name, variant):
    params = ModelParams().with_variant(variant)
    emf = None
    if params.source.emf == "held":
        emf = abs(prefault_flow(SCENARIO, np.zeros(5), params)[1])
    q = _setpoints(name)
    model = build_model(SCENARIO, q, params, emf)
    z = model.impedance()
    assert np.abs(model.derivatives(model.x0, z)).max() <= 1e-8
    v = model.voltages(model.x0, z)
    if emf is None:  # the slack at its scheduled voltage: the case's own power flow
        pf = solve_pf(NET, SCENARIO.injections(q[None])[0], tol=1e-12)
        assert np.abs(v - pf.v).max() <= 1e-8
    else:  # EMF held: the slack moves, the flow behind the source is the reference
        assert np.abs(v - model.v0).max() <= 1e-8
        assert abs(abs(model.emf) - emf) <= 1e-12
    # the inverters inject the strategy's setpoints
    assert np.abs(model.der_q_mvar(model.x0, v) - q).max() <= 1e-9


def test_no_fault_stays_put_for_three_seconds():
    model = build_model(SCENARIO, _setpoints("lfma"), ModelParams())
    sim = simulate(model, FaultParams(bus=18, duration_s=0.0, t_end_s=3.0))
    assert sim.ok
    assert np.abs(sim.vm - np.abs(model.v0)).max() <= 1e-6
    assert np.isnan(sim.recovery_ms()).sum() == 0 and sim.motors_stalled() == 0


def test_motor_keeps_the_load_and_draws_its_circuit_q():
    p = MotorParams()
    v = 0.95 * np.exp(0.1j)
    st = steady_state(p, v, p_mw=0.2, bus_label=5)
    s = v * np.conj(st.current)  # motor base
    assert s.real == pytest.approx(p.loading, rel=1e-12)
    assert st.q_mvar == pytest.approx(s.imag * 0.2 / p.loading, rel=1e-12)
    assert st.current == pytest.approx(v / impedance(p, st.slip), rel=1e-12)
    # static part keeps the rest: the model's total load equals the case's
    model = build_model(SCENARIO, _setpoints("no-action"), replace(ModelParams(), motors=p))
    assert model.n_motors == int((NET.load_p_mw > 0).sum())
