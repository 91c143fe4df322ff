"""Solve-time benchmark of the centralized formulations against pandapower's runopp.

`python -m opfbench.bench opf [--json]` runs `bench_opf` on paper33. Over n
snapshots of a smooth day (`daily_scenario`) it times, per snapshot and in one run:

- the AC OPF, IPOPT warm-started from the previous snapshot (wall time of the
  `AcOpf.solve` call, CasADi overhead included; IPOPT's own time alongside), and the
  same snapshots solved cold, for the iteration counts;
- the SOCP relaxation (`ConicModel.solve` call);
- pandapower `runopp` on every `PEER_EVERY`-th of those snapshots (`PandapowerOpf`;
  `pandapower_snapshots`: one runopp takes seconds, and on all n it took most of
  `bench all`'s time), with its losses checked against ours (our AC power flow at IPOPT's
  setpoints) where both converged.

and, on the paper day (1440 one-minute snapshots of real profiles, `bench.profiles`),
the registered strategies as the study runs them, everything included (SOCP solves,
the fast path's batched power flow, IPOPT where needed, the AC evaluation):

- `acopf_step_ms`: median over repeats of the `acopf` strategy's wall time / snapshots,
  each repeat on a fresh Scenario object with the solve cache emptied (so no shared SOCP
  solves), solver objects already built (their one-off build is
  `acopf_build_s`);
- `socp_step_ms`: the same for `socp` on a fresh scenario (its own Clarabel solves);
  `socp_shared_step_ms` / `acopf_paper_shared_step_ms`: `socp` / `acopf-paper` right
  after `acopf` on the same scenario and k (the solves are shared, what the study runner
  does: the paper's slack rule re-solves only where the slack exports);
- `certified_share`: share of snapshots the fast path certified (`certified_by` socp);
- `acopf_ipopt_step_ms`: `acopf` with `solver="ipopt"` (IPOPT on every snapshot), and
  `fast_path_max_rel_diff`: the largest relative difference of its losses from the
  fast path's.

and on 1-MV-rural (SimBench, 101 buses, 102 DER) over the paper day's date at 15 min of its
own profiles (`bench_mv`), the same per-step costs `mv_socp_step_ms` and `mv_acopf_step_ms`
(target ≤ 3 ms each), the certified share, and pandapower `runopp` on SimBench's own net
at every 12th step (`mv_pandapower_runopp_ms`, with its losses checked against our AC
OPF's at the same steps).

and where the physical limit of a relaxation answer lies (`bench_kkt`, `bench.kkt`) on
1-MV-rural and 1-LV-rural3 over the same day: the program's size, its KKT matrix's
nonzeros and fill, the flops of one factorization and of one iteration, Clarabel's
iterations per answer and CPU µs per iteration (`kkt_*_iteration_us`), against the LDLᵀ
refactor and two solves of the same matrix that an iteration cannot avoid (`kkt_*_ldl_us`,
its peer, the regression guard's ratio).

Medians in ms; `ratio_*` = pandapower median / ours. The machine's load average is
recorded because the timings depend on it.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from opfbench.bench.pandapower_opf import PandapowerOpf
from opfbench.bench.paper_day import paper_day_scenario
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.problem import snapshot_data
from opfbench.formulations.solves import forget_solves
from opfbench.io import load_case, load_network
from opfbench.network import Network
from opfbench.powerflow import solve_pf_batch
from opfbench.powerflow.memo import forget_flows
from opfbench.registry.catalog import run_strategy
from opfbench.result import CERTIFIED_BY_SOCP
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now

AGREEMENT_KW = 1e-2  # pandapower's and our optimal losses agree when this close
MV_CASE = "1-MV-rural--0-sw"
LV_CASE = "1-LV-rural3--0-sw"  # the suite's LV grid with the most costly relaxation answers
TARGET_MV_STEP_MS = 3.0
PEER_EVERY = 10  # pandapower runopp on every 10th snapshot of `bench_opf`'s day


def element_loads(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """(P, Q) (S, n_load) per load element: the scenario's own, or load_scale × the nominal
    load of a network with one load element per bus (the MATPOWER convention)."""
    if scenario.load_p_mw is not None and scenario.load_q_mvar is not None:
        return scenario.load_p_mw, scenario.load_q_mvar
    net = scenario.net
    assert scenario.load_scale is not None and np.unique(net.load_bus).size == net.n_load
    scale = scenario.load_scale[:, None]
    return scale * net.load_p_mw[net.load_bus], scale * net.load_q_mvar[net.load_bus]


def daily_scenario(net: Network, n: int = 200) -> Scenario:
    """n snapshots evenly over 24 h of a smooth synthetic day.

    Load scale 0.6 + 0.4·d(t), d(t) = (1 − cos(2π(t − 4 h)/24 h))/2 (low at 4 h, peak at
    16 h); PV at 0.9·rating·exp(−((t − 12.5 h)/2.8 h)²); DFIG at (0.55 + 0.3·sin(2πt/24 h
    + 1))·rating.
    """
    t = np.arange(n) * 24.0 / n
    load = 0.6 + 0.4 * 0.5 * (1 - np.cos(2 * np.pi * (t - 4) / 24))
    pv = 0.9 * np.exp(-(((t - 12.5) / 2.8) ** 2))
    wind = 0.55 + 0.3 * np.sin(2 * np.pi * t / 24 + 1)
    return Scenario.from_profiles(net, load, pv, wind)


def bench_opf(n: int = 200, case: str = "paper33", k: float = 0.0, peer_every: int = PEER_EVERY) -> dict:
    """Time IPOPT (warm) and SOCP over `n` snapshots, and pandapower runopp over every
    `peer_every`-th of them; see the module doc."""
    load_before = os.getloadavg()
    net = load_network(case)
    scenario = daily_scenario(net, n)
    data = snapshot_data(scenario, k)
    opf, relax = build_problem_model("exact", net), build_problem_model("relaxation", net)
    try:
        peer = PandapowerOpf.of_network(net)
    except ImportError:  # the peer is optional (pip install -e '.[bench]')
        peer = None

    warm, start_point = [], None
    ipopt_wall = np.empty(n)
    for i in range(n):
        t0 = now()
        sol = opf.solve(data.s_fixed[i], data.q_limit[i], start_point)
        ipopt_wall[i] = elapsed_ms(t0)
        warm.append(sol)
        start_point = sol if sol.success else start_point
    cold = [opf.solve(data.s_fixed[i], data.q_limit[i]) for i in range(n)]

    socp_wall = np.empty(n)
    socp = []
    for i in range(n):
        t0 = now()
        socp.append(relax.solve(data.s_fixed[i], data.q_limit[i]))
        socp_wall[i] = elapsed_ms(t0)

    q_mvar_limit = data.q_limit * net.base_mva
    load_p, load_q = element_loads(scenario)
    rows = np.arange(0, n, peer_every)
    peers = [] if peer is None else [peer.solve(load_p[i], load_q[i], scenario.der_p_mw[i], q_mvar_limit[i]) for i in rows]

    ipopt_ok = np.array([s.success for s in warm])
    q_opf = np.array([s.q_pu for s in warm]) * net.base_mva
    our_losses = np.where(ipopt_ok, solve_pf_batch(net, scenario.injections(q_opf)).losses_kw, np.nan)
    pp_ok = np.array([p.converged for p in peers], dtype=bool)
    diff = np.abs(np.array([p.losses_kw for p in peers]) - our_losses[rows])[ipopt_ok[rows] & pp_ok] if peers else np.zeros(0)
    socp_ok = np.array([s.optimal for s in socp])
    lower = np.array([s.objective_kw for s in socp])

    ipopt_ms = float(np.median(ipopt_wall))
    socp_ms = float(np.median(socp_wall))
    pp_ms = float(np.median([p.wall_ms for p in peers])) if peers else None
    return {
        "case": case,
        "k": k,
        "total": n,
        "solved": int((ipopt_ok & socp_ok).sum()),
        "solved_by_solver": {
            "ipopt": int(ipopt_ok.sum()),
            "socp": int(socp_ok.sum()),
            "pandapower": int(pp_ok.sum()) if peers else None,
        },
        "pandapower_snapshots": len(peers) if peers else None,
        "pandapower_failures": int((~pp_ok).sum()) if peers else None,
        "ipopt_ms": ipopt_ms,
        "socp_ms": socp_ms,
        "pandapower_runopp_ms": pp_ms,
        "ratio_ipopt_vs_pandapower": None if pp_ms is None else pp_ms / ipopt_ms,
        "ratio_socp_vs_pandapower": None if pp_ms is None else pp_ms / socp_ms,
        "ipopt_internal_ms": float(np.median([s.solve_ms for s in warm])),
        "ipopt_cold_ms": float(np.median([s.solve_ms for s in cold])),
        "ipopt_iterations_warm_mean": float(np.mean([s.iterations for s in warm])),
        "ipopt_iterations_cold_mean": float(np.mean([s.iterations for s in cold])),
        "pandapower_agrees": int((diff <= AGREEMENT_KW).sum()) if peers else None,
        "pandapower_max_loss_diff_kw": float(diff.max(initial=0.0)),
        "max_relative_gap": float(np.nanmax((our_losses - lower) / our_losses)),
        "loadavg_before": [round(x, 2) for x in load_before],
        "loadavg_after": [round(x, 2) for x in os.getloadavg()],
        "cpus": os.cpu_count(),
    }


def bench_paper_day(case: str = "paper33", k: float = 0.0, repeats: int = 3) -> dict:
    """Per-snapshot cost of the `acopf` and `socp` strategies on the paper day; see the module doc."""
    day = paper_day_scenario(case)
    n = day.n_snapshots

    def fresh() -> Scenario:  # a new Scenario object and no solves or flows kept by data: nothing shared
        forget_solves()
        forget_flows()
        return Scenario(day.net, day.load_scale, day.der_p_mw)

    def step_ms(strategy: str, scenario: Scenario, **options):
        start = now()
        res = run_strategy(strategy, scenario, k, **options)
        return elapsed_ms(start) / n, res

    start = now()
    run_strategy("acopf", day.take(slice(0, 10)), k, solver="ipopt")  # builds the per-thread SOCP and AC OPF
    build_s = elapsed_ms(start) / 1e3
    acopf_ms, socp_ms, shared_ms, paper_ms = [], [], [], []
    for _ in range(repeats):
        scenario = fresh()
        ms, fast = step_ms("acopf", scenario)
        acopf_ms.append(ms)
        shared_ms.append(step_ms("socp", scenario)[0])
        paper_ms.append(step_ms("acopf-paper", scenario)[0])
        socp_ms.append(step_ms("socp", fresh())[0])
    ipopt_ms, ipopt = step_ms("acopf", fresh(), solver="ipopt")
    both = np.isfinite(fast.losses_kw) & np.isfinite(ipopt.losses_kw)
    rel = np.abs(fast.losses_kw - ipopt.losses_kw)[both] / np.abs(ipopt.losses_kw[both])
    return {
        "paper_day_case": case,
        "paper_day_steps": n,
        "acopf_step_ms": float(np.median(acopf_ms)),
        "socp_step_ms": float(np.median(socp_ms)),
        "socp_shared_step_ms": float(np.median(shared_ms)),
        "acopf_paper_shared_step_ms": float(np.median(paper_ms)),
        "acopf_ipopt_step_ms": ipopt_ms,
        "acopf_build_s": build_s,
        "certified_share": float(np.mean(fast.solver.certified_by == CERTIFIED_BY_SOCP)),
        "acopf_not_ok_steps": int((fast.status != "ok").sum()),
        "fast_path_max_rel_diff": float(rel.max(initial=0.0)),
    }


def _span(values: np.ndarray) -> list[float | None]:
    """[min, max] of `values` ([None, None] when empty)."""
    return [float(values.min()), float(values.max())] if values.size else [None, None]


def bench_mv(code: str = MV_CASE, k: float = 0.0, repeats: int = 3, peer_every: int = 12) -> dict:
    """Per-step cost of `socp` and `acopf` on a SimBench MV grid over the paper day's date at
    15 min of its own profiles, each repeat on a fresh scenario with no solves shared; runopp
    on every `peer_every`-th step of SimBench's own net. See the module doc."""
    from opfbench.data import PAPER_DAY
    from opfbench.data.profiles import PAPER_DAY_TZ

    case = load_case(f"simbench:{code}")
    index = pd.date_range(PAPER_DAY, periods=96, freq="15min", tz=PAPER_DAY_TZ)
    assert case.series is not None and case.load_index is not None and case.der_index is not None
    load_p, load_q, der_p = case.series.rows(index)
    day = Scenario.from_series(case.balanced("the OPF benchmark"), load_p, load_q, der_p)
    n = day.n_snapshots

    def fresh() -> Scenario:
        forget_solves()
        forget_flows()
        return Scenario.from_series(day.net, load_p, load_q, der_p)

    def step_ms(strategy: str):
        scenario = fresh()
        start = now()
        res = run_strategy(strategy, scenario, k)
        return elapsed_ms(start) / n, res

    start = now()
    run_strategy("acopf", day.take(slice(0, 4)), k, solver="ipopt")  # builds the per-thread SOCP and AC OPF
    build_s = elapsed_ms(start) / 1e3
    socp_ms, acopf_ms = [], []
    for _ in range(repeats):
        socp_ms.append(step_ms("socp")[0])
        ms, acopf = step_ms("acopf")
        acopf_ms.append(ms)
    rows = np.arange(0, n, peer_every)
    socp_step, acopf_step = float(np.median(socp_ms)), float(np.median(acopf_ms))
    out: dict[str, object] = {
        "mv_case": code,
        "mv_steps": n,
        "mv_buses": case.network.n_bus,
        "mv_ders": len(case.network.ders),
        "mv_socp_step_ms": socp_step,
        "mv_acopf_step_ms": acopf_step,
        "mv_socp_step_ms_runs": socp_ms,
        "mv_acopf_step_ms_runs": acopf_ms,
        "mv_build_s": build_s,
        "mv_certified_share": float(np.mean(acopf.solver.certified_by == CERTIFIED_BY_SOCP)),
        "mv_acopf_not_ok_steps": int((acopf.status != "ok").sum()),
        "mv_target_step_ms": TARGET_MV_STEP_MS,
        "mv_pandapower_runopp_ms": None,
    }
    try:
        peer = PandapowerOpf.of_simbench(code, case.load_index, case.der_index)
    except ImportError:
        return out
    q_limit = (1.0 - k) * day.qmax_mvar()
    peers = [peer.solve(load_p[i], load_q[i], der_p[i], q_limit[i]) for i in rows]
    ok = np.array([p.converged for p in peers], dtype=bool)
    # runopp's setpoints in the AC power flow (ours = pandapower's runpp to 1e-8 kW on SimBench):
    # what its solution loses against our certified optimum; and its OPF's own reported losses,
    # which on SimBench's transformers differ from its power flow at the same setpoints
    q_pp = np.array([p.q_mvar for p in peers])[ok]
    at_pp = solve_pf_batch(day.net, day.take(rows[ok]).injections(q_pp)).losses_kw if ok.any() else np.zeros(0)
    excess = at_pp - acopf.losses_kw[rows[ok]]
    model_gap = np.array([p.losses_kw for p in peers])[ok] - at_pp
    pp_ms = float(np.median([p.wall_ms for p in peers]))
    return out | {
        "mv_pandapower_runopp_ms": pp_ms,
        "mv_pandapower_snapshots": len(rows),
        "mv_pandapower_failures": int((~ok).sum()),
        "mv_pandapower_excess_kw": _span(excess),
        "mv_pandapower_opf_vs_pf_kw": _span(model_gap),
        "ratio_mv_socp_step_vs_pandapower": pp_ms / socp_step,
        "ratio_mv_acopf_step_vs_pandapower": pp_ms / acopf_step,
    }


def bench_kkt(grids: tuple[tuple[str, str], ...] = (("mv", MV_CASE), ("lv", LV_CASE)), k: float = 0.0) -> dict:
    """Where the physical limit of a relaxation answer lies (`bench.kkt`), on each grid
    (tag, SimBench code) over the paper day's date at 15 min of its own profiles: keys
    `kkt_{tag}_*` (dimensions, KKT nonzeros, fill, flops, Clarabel's iterations and CPU µs
    per iteration, and the LDLᵀ refactor and two solves of the same KKT matrix, its peer)."""
    from opfbench.bench.kkt import kkt_figures
    from opfbench.data import PAPER_DAY
    from opfbench.data.profiles import PAPER_DAY_TZ
    from opfbench.formulations.models.conic import data_vector

    out: dict[str, object] = {}
    for tag, code in grids:
        case = load_case(f"simbench:{code}")
        assert case.series is not None
        index = pd.date_range(PAPER_DAY, periods=96, freq="15min", tz=PAPER_DAY_TZ)
        day = Scenario.from_series(case.balanced("the KKT benchmark"), *case.series.rows(index))
        model = build_problem_model("relaxation", day.net)
        data = snapshot_data(day, k)
        offsets = model.program.offsets(data_vector(data.s_fixed, data.q_limit))
        out[f"kkt_{tag}_case"] = code
        out |= {f"kkt_{tag}_{key}": value for key, value in kkt_figures(model.program, offsets).items()}
    return out


def run() -> dict:
    day = bench_paper_day()
    figures = bench_opf()
    pp_ms = figures["pandapower_runopp_ms"]
    figures |= day | {
        "ratio_acopf_step_vs_pandapower": None if pp_ms is None else pp_ms / day["acopf_step_ms"],
        "ratio_socp_step_vs_pandapower": None if pp_ms is None else pp_ms / day["socp_step_ms"],
    }
    figures |= bench_mv()
    figures |= bench_kkt()
    figures["loadavg_after"] = [round(x, 2) for x in os.getloadavg()]
    return figures


def print_table(f: dict) -> None:
    def versus(ratio: float | None) -> str:
        return "pandapower not installed" if ratio is None else f"{ratio:.0f}× pandapower"

    print(f"centralized formulations on {f['case']}, {f['total']} snapshots of a smooth day, k = {f['k']}")
    print(
        f"  IPOPT warm-started    {f['ipopt_ms']:.2f} ms median  ({f['ipopt_iterations_warm_mean']:.1f} iterations; "
        f"cold {f['ipopt_iterations_cold_mean']:.1f})  → {versus(f['ratio_ipopt_vs_pandapower'])}"
    )
    print(
        f"  SOCP (Clarabel)       {f['socp_ms']:.2f} ms median  → {versus(f['ratio_socp_vs_pandapower'])}"
        f"  (largest relative gap {f['max_relative_gap']:.1e})"
    )
    if f["pandapower_runopp_ms"] is not None:
        print(
            f"  pandapower runopp     {f['pandapower_runopp_ms']:.1f} ms median of {f['pandapower_snapshots']} snapshots, "
            f"{f['pandapower_failures']} failures, "
            f"agrees on {f['pandapower_agrees']} (max |Δ| {f['pandapower_max_loss_diff_kw']:.1e} kW)"
        )
    print(f"  solved by both ours   {f['solved']}/{f['total']}   load average {f['loadavg_before']} → {f['loadavg_after']}")
    if "acopf_step_ms" not in f:  # `bench_opf` alone (without `bench_paper_day`)
        return
    print(f"paper day on {f['paper_day_case']}, {f['paper_day_steps']} steps, per step, everything included:")
    print(
        f"  acopf (fast path)     {f['acopf_step_ms']:.2f} ms  → {versus(f['ratio_acopf_step_vs_pandapower'])};"
        f" certified by the SOCP {f['certified_share']:.1%}, largest relative difference from IPOPT"
        f" {f['fast_path_max_rel_diff']:.1e}"
    )
    print(f"  acopf (IPOPT always)  {f['acopf_ipopt_step_ms']:.2f} ms")
    print(
        f"  socp                  {f['socp_step_ms']:.2f} ms  (after acopf on the same scenario:"
        f" {f['socp_shared_step_ms']:.3f} ms) → {versus(f['ratio_socp_step_vs_pandapower'])}"
    )
    if "mv_socp_step_ms" not in f:
        return
    print(
        f"{f['mv_case']} ({f['mv_buses']} buses, {f['mv_ders']} DER), {f['mv_steps']} steps of its own profiles, per step "
        f"(target ≤ {f['mv_target_step_ms']:g} ms):"
    )
    print(
        f"  socp                  {f['mv_socp_step_ms']:.2f} ms  (runs {', '.join(f'{v:.2f}' for v in f['mv_socp_step_ms_runs'])})"
    )
    print(
        f"  acopf (fast path)     {f['mv_acopf_step_ms']:.2f} ms  (runs {', '.join(f'{v:.2f}' for v in f['mv_acopf_step_ms_runs'])});"
        f" certified by the SOCP {f['mv_certified_share']:.1%}"
    )
    if f["mv_pandapower_runopp_ms"] is not None:
        print(
            f"  pandapower runopp     {f['mv_pandapower_runopp_ms']:.1f} ms median on {f['mv_pandapower_snapshots']} steps, "
            f"{f['mv_pandapower_failures']} failures; its setpoints lose {f['mv_pandapower_excess_kw'][0]:.3g} … "
            f"{f['mv_pandapower_excess_kw'][1]:.3g} kW to our AC OPF (its own OPF reports "
            f"{f['mv_pandapower_opf_vs_pf_kw'][0]:.3g} … {f['mv_pandapower_opf_vs_pf_kw'][1]:.3g} kW vs its power flow)"
        )
    for tag in ("mv", "lv"):
        if f"kkt_{tag}_case" not in f:
            continue
        g = {key[len(f"kkt_{tag}_") :]: value for key, value in f.items() if key.startswith(f"kkt_{tag}_")}
        print(
            f"relaxation on {g['case']}: {g['variables']} variables, {g['rows']} rows ({g['soc_cones']} SOC); KKT dim "
            f"{g['kkt_dim']}, {g['kkt_nnz']} nonzeros, L {g['ldl_nnz']} (fill {g['fill']:.2f}); "
            f"{g['iteration_kflop']:.0f} kflop per iteration ({g['factor_kflop']:.0f} the factorization)"
        )
        print(
            f"  Clarabel {g['iterations_median']:.0f} iterations per answer (median), {g['iteration_us']:.0f} µs CPU each, "
            f"{g['answer_ms_median']:.2f} ms an answer; LDLᵀ refactor + 2 solves {g['ldl_us']:.0f} µs "
            f"({g['ldl_gflops']:.2f} GFlop/s): an iteration is {g['iteration_over_ldl']:.1f}× its factorization"
        )
