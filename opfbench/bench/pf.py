"""Power-flow benchmark on `paper33`: single NR solve, the batched solver on the 1440
snapshots of the paper day (DER Q = 0), and the same 1440 snapshots through pandapower `runpp` (a loop, as a user
of pandapower would run a time series) and power-grid-model's batch calculation.
Our solves, power-grid-model's batch and the pandapower loop (all single-threaded) are timed
by CPU time, ours and power-grid-model's as the best of several calls
(`opfbench.timing.best_ms`, `cpu=True`: the same as wall time on a quiet machine, and not
inflated by waiting for a core on a shared one). The pandapower loop runs every
`PANDAPOWER_EVERY`-th snapshot (`pandapower_loop_snapshots` of them: one runpp costs
about the same on every snapshot, and the whole loop took minutes of `bench all`);
`pandapower_loop_1440_ms` is its time scaled to the 1440 snapshots. `batch_vs_single_max_dv_pu`
checks the batched solver against Newton–Raphson on every 60th snapshot; the peers'
voltages are compared with ours on every snapshot they solved.

With `--large` the large-feeder figures of `opfbench.bench.pf_large` are added.
"""

from __future__ import annotations

import argparse
import importlib.util
import warnings

import numpy as np

from opfbench.bench.paper_day import paper_day_scenario
from opfbench.errors import NetworkError
from opfbench.io.matpower import to_ppc
from opfbench.network import Network
from opfbench.powerflow import bus_injections, solve_pf, solve_pf_batch
from opfbench.powerflow.memo import cold
from opfbench.timing import best_ms

NUMBA = importlib.util.find_spec("numba") is not None  # pandapower's fast path, when installed
BATCH_REPEATS, PEER_REPEATS = 100, 15  # calls timed (best kept) of our batch and of power-grid-model's
PANDAPOWER_EVERY = 10  # the pandapower loop runs every 10th snapshot of the day (module docstring)


def pandapower_net(net: Network):
    """pandapower net of `net` (the one MATPOWER-dict exporter `to_ppc`, so line charging,
    taps, shifts, shunts and fixed generators are kept) with its case loads removed and
    one load per bus, for `set_injections`."""
    import pandapower as pp
    from pandapower.converter.pypower import from_ppc

    ppc = to_ppc(net)
    ppc["bus"][:, 2:4] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pnet = from_ppc(ppc, f_hz=50)
    pp.create_loads(pnet, pnet.bus.index.to_numpy(), p_mw=0.0, q_mvar=0.0)
    return pnet


def set_injections(pnet, net: Network, s_mw: np.ndarray) -> None:
    """Set the per-bus loads of `pandapower_net(net)` so the bus injections equal `s_mw`
    (n_bus,) complex MW: load = −(s − the case's fixed generation, which pandapower holds)."""
    load = -(s_mw - bus_injections(net, 0.0, 0.0, 0.0))
    pnet.load["p_mw"] = load.real
    pnet.load["q_mvar"] = load.imag


def _pandapower_loop_ms(net: Network, s_mw: np.ndarray, every: int = PANDAPOWER_EVERY) -> tuple[float | None, float | None]:
    """(CPU ms for runpp over every `every`-th snapshot of `s_mw`, scaled to all of them;
    max |V| difference to ours on those, p.u.), or (None, None) when pandapower is not
    installed."""
    try:
        import pandapower as pp
    except ImportError:
        return None, None

    pnet = pandapower_net(net)
    rows = s_mw[::every]
    vm = np.empty((len(rows), net.n_bus))

    def loop() -> None:
        for i, row in enumerate(rows):
            set_injections(pnet, net, row)
            pp.runpp(pnet, tolerance_mva=1e-8, numba=NUMBA)
            vm[i] = pnet.res_bus.vm_pu.to_numpy()

    elapsed, _ = best_ms(loop, 1, cpu=True)
    return elapsed * len(s_mw) / len(rows), float(np.abs(vm - np.abs(solve_pf_batch(net, rows).v)).max())


def _pgm_batch_ms(net: Network, s_mw: np.ndarray) -> tuple[float | None, float | None]:
    """(CPU ms of power-grid-model's batch power flow, max |V| difference p.u.), or
    (None, None) when power-grid-model is not installed. The model is built from series
    r/x only, so a case with line charging, taps, shunts or fixed generators is refused."""
    plain = not (
        net.b.any() or (net.tap != 1).any() or net.shift.any() or net.gs_mw.any() or net.bs_mvar.any() or net.gen_bus.size
    )
    if not plain:
        raise NetworkError(f"{net.name}: the power-grid-model peer models plain series lines only")
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
    model = PowerGridModel(
        {ComponentType.node: node, ComponentType.line: line, ComponentType.source: source, ComponentType.sym_load: load},
        system_frequency=50.0,
    )
    update = initialize_array(DatasetType.update, ComponentType.sym_load, (len(s_mw), n))
    update["id"] = load["id"][None, :]
    update["p_specified"] = -s_mw.real * 1e6
    update["q_specified"] = -s_mw.imag * 1e6

    def run():
        return model.calculate_power_flow(
            update_data={ComponentType.sym_load: update},
            symmetric=True,
            error_tolerance=1e-10,
            max_iterations=30,
            calculation_method=CalculationMethod.newton_raphson,
        )

    ms, out = best_ms(run, PEER_REPEATS, cpu=True)
    vm = out[ComponentType.node]["u_pu"]
    return ms, float(np.abs(vm - np.abs(solve_pf_batch(net, s_mw).v)).max())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--large", action="store_true", help="add the large-feeder figures (feeder10k)")


def run(args: argparse.Namespace | None = None) -> dict:
    """The paper33 figures; with `--large`, also the large-feeder ones (`pf_large.run_large`)."""
    large = bool(args is not None and args.large)
    day = paper_day_scenario("paper33")
    net = day.net
    s_one = bus_injections(net, 0.8 * net.der_rating_mw)
    s_day = day.injections(np.zeros_like(day.der_p_mw))  # every DER at Q = 0
    solve_pf_batch(net, s_day)  # factor once, warm caches
    single_ms, _ = best_ms(lambda: solve_pf(net, s_one), 300, cpu=True)
    batch_ms, batch = best_ms(lambda: cold(solve_pf_batch, net, s_day), BATCH_REPEATS, cpu=True)
    sample = np.arange(0, day.n_snapshots, 60)
    dv_single = max(float(np.abs(batch.v[k] - solve_pf(net, s_day[k]).v).max()) for k in sample)
    pp_ms, pp_dv = _pandapower_loop_ms(net, s_day)
    pgm_ms, pgm_dv = _pgm_batch_ms(net, s_day)
    figures = {
        "case": net.name,
        "snapshots": day.n_snapshots,
        "single_ms": single_ms,
        "batch_1440_ms": batch_ms,
        "batch_converged": int(batch.converged.sum()),
        "batch_max_iterations": int(batch.iterations.max()),
        "batch_vs_single_max_dv_pu": dv_single,
        "pandapower_loop_1440_ms": pp_ms,
        "pandapower_loop_snapshots": None if pp_ms is None else len(s_day[::PANDAPOWER_EVERY]),
        "ratio_vs_pandapower": None if pp_ms is None else pp_ms / batch_ms,
        "pandapower_max_dv_pu": pp_dv,
        "pandapower_numba": NUMBA,
        "pgm_batch_1440_ms": pgm_ms,
        "ratio_vs_pgm": None if pgm_ms is None else pgm_ms / batch_ms,
        "pgm_max_dv_pu": pgm_dv,
    }
    if large:
        from opfbench.bench.pf_large import run_large

        figures |= run_large()
    return figures


def print_table(f: dict) -> None:
    print(f"power flow on {f['case']}, {f['snapshots']} snapshots of the paper day")
    print(f"  single NR solve              {f['single_ms']:.3f} ms")
    print(
        f"  batched solver, 1440 steps   {f['batch_1440_ms']:.2f} ms  ({f['batch_converged']} converged, ≤ {f['batch_max_iterations']} iterations, "
        f"max |ΔV| vs NR {f['batch_vs_single_max_dv_pu']:.1e} p.u.)"
    )
    numba = "with numba" if f["pandapower_numba"] else "without numba"
    if f["pandapower_loop_1440_ms"] is None:
        print("  pandapower                   not installed")
    else:
        print(
            f"  pandapower runpp loop ({numba}, {f['pandapower_loop_snapshots']} snapshots, scaled to 1440) {f['pandapower_loop_1440_ms']:.0f} ms  → ours is {f['ratio_vs_pandapower']:.0f}× faster (max |ΔV| {f['pandapower_max_dv_pu']:.1e} p.u.)"
        )
    if f["pgm_batch_1440_ms"] is None:
        print("  power-grid-model            not installed")
    else:
        print(
            f"  power-grid-model batch       {f['pgm_batch_1440_ms']:.2f} ms  → ratio {f['ratio_vs_pgm']:.2f} (max |ΔV| {f['pgm_max_dv_pu']:.1e} p.u.)"
        )
    if "large_case" in f:
        from opfbench.bench.pf_large import print_large

        print_large(f)
