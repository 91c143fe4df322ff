"""Power-flow benchmark on `paper33`: single NR solve, the batched solver on the 1440
snapshots of the paper day (DER Q = 0), and the same 1440 snapshots through pandapower `runpp` (a loop, as a user
of pandapower would run a time series) and power-grid-model's batch calculation."""

from __future__ import annotations

import importlib.util
import time
from statistics import median

import numpy as np

from opfbench.bench.profiles import paper_day_scenario
from opfbench.network import Network
from opfbench.powerflow import bus_injections, solve_pf, solve_pf_batch

NUMBA = importlib.util.find_spec("numba") is not None  # pandapower's fast path, when installed


def _best_ms(fn, repeat: int) -> float:
    """Median wall time of `repeat` calls (ms)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return median(times)


def _pandapower_loop_ms(net: Network, s_mw: np.ndarray) -> tuple[float | None, float | None]:
    """(wall ms for runpp over all snapshots, max |V| difference to ours p.u.), or
    (None, None) when pandapower is not installed."""
    try:
        import pandapower as pp
    except ImportError:
        return None, None

    pnet = pp.create_empty_network(sn_mva=net.base_mva)
    buses = [pp.create_bus(pnet, vn_kv=float(kv)) for kv in net.base_kv]
    pp.create_ext_grid(pnet, buses[net.slack], vm_pu=net.v_slack)
    for k in np.flatnonzero(net.status):
        zbase = net.base_kv[net.f[k]] ** 2 / net.base_mva
        pp.create_line_from_parameters(pnet, buses[net.f[k]], buses[net.t[k]], length_km=1.0,
                                       r_ohm_per_km=net.r[k] * zbase, x_ohm_per_km=net.x[k] * zbase,
                                       c_nf_per_km=0.0, max_i_ka=10.0)
    for b in buses:
        pp.create_load(pnet, b, p_mw=0.0, q_mvar=0.0)
    vm = np.empty((len(s_mw), net.n_bus))
    t0 = time.perf_counter()
    for i, row in enumerate(s_mw):
        pnet.load["p_mw"] = -row.real
        pnet.load["q_mvar"] = -row.imag
        pp.runpp(pnet, tolerance_mva=1e-8, numba=NUMBA)
        vm[i] = pnet.res_bus.vm_pu.to_numpy()
    elapsed = (time.perf_counter() - t0) * 1e3
    return elapsed, float(np.abs(vm - np.abs(solve_pf_batch(net, s_mw).v)).max())


def _pgm_batch_ms(net: Network, s_mw: np.ndarray) -> tuple[float | None, float | None]:
    """(wall ms of power-grid-model's batch power flow, max |V| difference p.u.), or
    (None, None) when power-grid-model is not installed."""
    try:
        from power_grid_model import CalculationMethod, ComponentType, DatasetType, LoadGenType, PowerGridModel, initialize_array
    except ImportError:
        return None, None
    n, on = net.n_bus, np.flatnonzero(net.status)
    node = initialize_array(DatasetType.input, ComponentType.node, n)
    node["id"] = np.arange(n)
    node["u_rated"] = net.base_kv * 1e3
    line = initialize_array(DatasetType.input, ComponentType.line, len(on))
    zbase = net.base_kv[net.f[on]] ** 2 / net.base_mva
    line["id"] = n + np.arange(len(on))
    line["from_node"], line["to_node"] = net.f[on], net.t[on]
    line["from_status"] = line["to_status"] = 1
    line["r1"], line["x1"] = net.r[on] * zbase, net.x[on] * zbase
    line["c1"], line["tan1"], line["i_n"] = 0.0, 0.0, 1e4
    source = initialize_array(DatasetType.input, ComponentType.source, 1)
    source["id"], source["node"], source["status"] = n + len(on), net.slack, 1
    source["u_ref"], source["sk"] = net.v_slack, 1e40
    load = initialize_array(DatasetType.input, ComponentType.sym_load, n)
    load["id"] = n + len(on) + 1 + np.arange(n)
    load["node"], load["status"], load["type"] = np.arange(n), 1, LoadGenType.const_power
    model = PowerGridModel({ComponentType.node: node, ComponentType.line: line,
                            ComponentType.source: source, ComponentType.sym_load: load}, system_frequency=50.0)
    update = initialize_array(DatasetType.update, ComponentType.sym_load, (len(s_mw), n))
    update["id"] = load["id"][None, :]
    update["p_specified"] = -s_mw.real * 1e6
    update["q_specified"] = -s_mw.imag * 1e6

    def run():
        return model.calculate_power_flow(update_data={ComponentType.sym_load: update}, symmetric=True,
                                          error_tolerance=1e-10, max_iterations=30,
                                          calculation_method=CalculationMethod.newton_raphson)

    ms = _best_ms(run, 5)
    vm = run()[ComponentType.node]["u_pu"]
    return ms, float(np.abs(vm - np.abs(solve_pf_batch(net, s_mw).v)).max())


def run() -> dict:
    day = paper_day_scenario("paper33")
    net = day.net
    s_one = bus_injections(net, 0.8 * net.der_rating_mw)
    s_day = day.injections(0.0)
    solve_pf_batch(net, s_day)  # factor once, warm caches
    single_ms = _best_ms(lambda: solve_pf(net, s_one), 300)
    batch_ms = _best_ms(lambda: solve_pf_batch(net, s_day), 30)
    batch = solve_pf_batch(net, s_day)
    pp_ms, pp_dv = _pandapower_loop_ms(net, s_day)
    pgm_ms, pgm_dv = _pgm_batch_ms(net, s_day)
    return {
        "case": net.name,
        "snapshots": day.n_snapshots,
        "single_ms": single_ms,
        "batch_1440_ms": batch_ms,
        "batch_converged": int(batch.converged.sum()),
        "batch_max_iterations": int(batch.iterations.max()),
        "pandapower_loop_1440_ms": pp_ms,
        "ratio_vs_pandapower": None if pp_ms is None else pp_ms / batch_ms,
        "pandapower_max_dv_pu": pp_dv,
        "pandapower_numba": NUMBA,
        "pgm_batch_1440_ms": pgm_ms,
        "ratio_vs_pgm": None if pgm_ms is None else pgm_ms / batch_ms,
        "pgm_max_dv_pu": pgm_dv,
    }


def print_table(f: dict) -> None:
    print(f"power flow on {f['case']}, {f['snapshots']} snapshots of the paper day")
    print(f"  single NR solve              {f['single_ms']:.3f} ms")
    print(f"  batched solver, 1440 steps   {f['batch_1440_ms']:.2f} ms  ({f['batch_converged']} converged, ≤ {f['batch_max_iterations']} iterations)")
    numba = "with numba" if f["pandapower_numba"] else "without numba"
    if f["pandapower_loop_1440_ms"] is None:
        print("  pandapower                   not installed")
    else:
        print(f"  pandapower runpp loop ({numba}) {f['pandapower_loop_1440_ms']:.0f} ms  → ours is {f['ratio_vs_pandapower']:.0f}× faster (max |ΔV| {f['pandapower_max_dv_pu']:.1e} p.u.)")
    if f["pgm_batch_1440_ms"] is None:
        print("  power-grid-model            not installed")
    else:
        print(f"  power-grid-model batch       {f['pgm_batch_1440_ms']:.2f} ms  → ratio {f['ratio_vs_pgm']:.2f} (max |ΔV| {f['pgm_max_dv_pu']:.1e} p.u.)")
