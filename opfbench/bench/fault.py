"""Sub-benchmark: the RMS fault simulation — one 3-s run at 1 ms on `paper33` (after
compilation, best of 5), the study with a fault at every bus, and ANDES on the mild
fault of the validation (when installed) in the same process.

    python -m opfbench.bench fault [--json]

Keys: sim_ms, study_s, andes_sim_ms, ratio_vs_andes (null where ANDES is absent).
ratio_vs_andes = ANDES's wall time for its 1-s run over ours for the 3-s run
(conservative: ANDES simulates a third of the time).
"""

from __future__ import annotations

import os

from opfbench.dynamics.params import FaultParams, ModelParams
from opfbench.dynamics.point import operating_point
from opfbench.dynamics.rms_model import build_model
from opfbench.dynamics.simulate import simulate
from opfbench.dynamics.study import FaultConfig, run_fault_study
from opfbench.io import load_case
from opfbench.registry.catalog import run_strategy
from opfbench.timing import best_ms


def run() -> dict:
    case = load_case("paper33")
    net = case.balanced("the fault benchmark")
    point = operating_point(net)
    model = build_model(point.scenario, run_strategy("lfma", point.scenario, 0.0).q_mvar[0], ModelParams())
    fault = FaultParams(bus=27)
    simulate(model, fault)  # compile (or load numba's cache)
    sim_ms, sim = best_ms(lambda: simulate(model, fault), 5)
    workers = min(2, os.cpu_count() or 1)
    config = FaultConfig("paper33", tuple(int(b) for b in net.bus_ids), forecasts=("off", "oracle"))
    timings = run_fault_study(config, case, workers=workers).timings
    from opfbench.dynamics.andes_ref import MILD_FAULT, andes_available, mild_fault_comparison

    andes_ms = mild_fault_comparison()["andes_sim_ms"] if andes_available() else None
    return {
        "case": "paper33",
        "sim_ms": sim_ms,
        "steps": int(len(sim.t) - 1),
        "study_s": timings["study_s"],
        "study_simulations": timings["simulations"],
        "study_workers": workers,
        "andes_sim_ms": andes_ms,
        "andes_t_end_s": MILD_FAULT.t_end_s,
        "ratio_vs_andes": None if andes_ms is None else andes_ms / sim_ms,
    }


def print_table(f: dict) -> None:
    print(f"fault simulation on {f['case']}: one 3-s run, {f['steps']} steps: {f['sim_ms']:.1f} ms (best of 5)")
    print(
        f"study, a fault at every bus: {f['study_simulations']} simulations in {f['study_s']:.1f} s "
        f"on {f['study_workers']} worker(s)"
    )
    if f["andes_sim_ms"] is None:
        print("ANDES: not installed")
    else:
        print(
            f"ANDES on the mild fault ({f['andes_t_end_s']:g} s simulated, fixed 1-ms step): {f['andes_sim_ms']:.0f} ms "
            f"→ ours (3 s simulated) is {f['ratio_vs_andes']:.0f}× faster"
        )
