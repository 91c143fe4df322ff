"""One fault simulation on a `DynamicModel` and its measures: recovery time per bus
(fault inception until |V| stays ≥ 0.9 p.u. to the end), min |V|, voltage margin,
motors stalled."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from opfbench.dynamics import kernel
from opfbench.dynamics.params import RECOVERY_PU, FaultParams, ModelParams
from opfbench.dynamics.rms_model import DynamicModel
from opfbench.errors import InputError
from opfbench.network import Network
from opfbench.timing import elapsed_ms, now

TRACE_EVERY_S = 0.005  # traces: one sample per 5 ms
MARGIN_WINDOW_S = 0.100  # voltage margin: the last 100 ms


@dataclass(frozen=True, eq=False)
class Simulation:
    """Outcome of one run. t (K,) s and vm (K, n) |V| p.u. at every step; t_trace,
    vm_trace (all buses) and q_trace_mvar (DER buses) every 5 ms; x_end the final state;
    ok False when the simulation diverged (arrays end at the failure)."""

    model: DynamicModel
    fault: FaultParams
    fault_index: int
    t: np.ndarray
    vm: np.ndarray
    t_trace: np.ndarray
    vm_trace: np.ndarray
    q_trace_mvar: np.ndarray
    x_end: np.ndarray
    ok: bool
    sim_ms: float

    def recovery_ms(self) -> np.ndarray:
        """Per bus: ms from fault inception until |V| ≥ 0.9 p.u. for good (crossing
        linearly interpolated between steps); 0 if |V| never went below; NaN if it ends
        below or the run diverged."""
        return recovery_ms(self.t, self.vm, self.fault.t_on_s, self.ok)

    def vmin(self) -> np.ndarray:
        """Per bus: the lowest |V| from fault inception on (p.u.)."""
        return self.vm[self.t >= self.fault.t_on_s - 1e-12].min(axis=0)

    def margin_pu(self) -> np.ndarray:
        """Per bus: min |V| − 0.9 over the last 100 ms (negative if below)."""
        if not self.ok:
            return np.full(self.vm.shape[1], np.nan)
        return self.vm[self.t >= self.t[-1] - MARGIN_WINDOW_S - 1e-12].min(axis=0) - RECOVERY_PU

    def motors_stalled(self) -> int:
        """Motors whose final slip is beyond the breakdown slip."""
        nm = self.model.n_motors
        return int(np.sum(self.x_end[2 * nm : 3 * nm] > self.model.breakdown_slip))


def recovery_ms(t: np.ndarray, vm: np.ndarray, t_on: float, ok: bool = True) -> np.ndarray:
    """See `Simulation.recovery_ms`; t (K,), vm (K, n)."""
    n = vm.shape[1]
    if not ok:
        return np.full(n, np.nan)
    out = np.zeros(n)
    after = t >= t_on - 1e-12
    for b in range(n):
        below = np.flatnonzero(after & (vm[:, b] < RECOVERY_PU))
        if below.size == 0:
            continue
        last = below[-1]
        if last == len(t) - 1:
            out[b] = np.nan
            continue
        v1, v2 = vm[last, b], vm[last + 1, b]
        frac = (RECOVERY_PU - v1) / (v2 - v1)
        out[b] = (t[last] + frac * (t[last + 1] - t[last]) - t_on) * 1e3
    return out


def check_fault(net: Network, params: ModelParams, fault: FaultParams) -> int:
    """Validate the fault and the step against the model; return the internal fault bus."""
    if fault.bus not in set(int(b) for b in net.bus_ids):
        raise InputError(f"{net.name}: no bus {fault.bus} to fault (buses {net.bus_ids.min()}..{net.bus_ids.max()})")
    for label, value in (
        ("fault impedance", fault.impedance_pu),
        ("fault duration", fault.duration_s),
        ("fault inception", fault.t_on_s),
    ):
        if not math.isfinite(value) or value < 0:
            raise InputError(f"{label} must be ≥ 0, got {value}")
    if not fault.step_s > 0:
        raise InputError(f"time step must be > 0, got {fault.step_s * 1e3:g} ms")
    fastest = min(params.inverters.t_filter_s, params.inverters.t_lag_s)
    if fault.step_s > fastest / 2:
        raise InputError(
            f"time step {fault.step_s * 1e3:g} ms is too large for the fastest time constant "
            f"{fastest * 1e3:g} ms (at most {fastest / 2 * 1e3:g} ms)"
        )
    if not fault.t_end_s > fault.t_on_s + fault.duration_s:
        raise InputError(
            f"simulation end {fault.t_end_s:g} s (--t-end) must lie after the fault clears at "
            f"{fault.t_on_s + fault.duration_s:g} s (inception {fault.t_on_s:g} s + duration {fault.duration_s * 1e3:g} ms, "
            "--duration-ms)"
        )
    steps = sum(math.ceil(length / fault.step_s - 1e-9) for length, _ in segments(fault))
    need = 8.0 * (steps + 1) * (net.n_bus + 1)  # the time and every bus's |V| at every step, float64
    if need > MEMORY_SHARE * physical_memory():
        raise InputError(
            f"a simulation of {fault.t_end_s:g} s at a {fault.step_s * 1e3:g}-ms step is {steps:.3g} steps, and it keeps "
            f"|V| of {net.n_bus} buses at every step ({need / 1e9:.3g} GB, more than {MEMORY_SHARE:.0%} of this machine's "
            f"{physical_memory() / 1e9:.3g} GB): lengthen the step (--step-ms) or shorten the simulated time (--t-end)"
        )
    return net.index_of(fault.bus)


MEMORY_SHARE = 0.25  # the most of the machine's memory one simulation's samples may take (workers run several)


def physical_memory() -> float:
    """This machine's memory, bytes."""
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def segments(fault: FaultParams) -> list[tuple[float, bool]]:
    """(length s, faulted) of the pre-fault, fault and post-fault intervals (empty ones dropped)."""
    parts = [(fault.t_on_s, False), (fault.duration_s, True), (fault.t_end_s - fault.t_on_s - fault.duration_s, False)]
    return [(length, on) for length, on in parts if length > 1e-12]


def simulate(model: DynamicModel, fault: FaultParams) -> Simulation:
    """Run `fault` on `model` with fixed-step RK4."""
    fb = check_fault(model.net, model.params, fault)
    start = now()
    z_pre = model.impedance()
    z_fault = model.impedance(fb, fault.impedance_pu)
    segs = segments(fault)
    zs = np.stack([z_fault if on else z_pre for _, on in segs])
    steps = np.array([max(1, math.ceil(length / fault.step_s - 1e-9)) for length, _ in segs], dtype=np.int64)
    hs = np.array([length for length, _ in segs]) / steps
    every = max(1, int(round(TRACE_EVERY_S / fault.step_s)))
    t, vm, t_tr, vm_tr, q_tr, x_end, ok = kernel.integrate(
        model.x0,
        np.ascontiguousarray(zs.real),
        np.ascontiguousarray(zs.imag),
        steps,
        hs,
        model.i_const,
        model.mot_bus,
        model.mot_y,
        model.mot_par,
        model.inv_bus,
        model.inv_par,
        model.scalars,
        model.v0[model.inv_bus].copy(),
        every,
    )
    return Simulation(model, fault, fb, t, vm, t_tr, vm_tr, q_tr * model.net.base_mva, x_end, bool(ok), elapsed_ms(start))
