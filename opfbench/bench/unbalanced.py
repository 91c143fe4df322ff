"""The three-phase power flow and rules against OpenDSS in this process
(`python -m opfbench.bench unbalanced [--json]`), on the same loads and PV:

- `eulv_day_ms` / `eulv_dss_daily_ms`: the `eulv` paper day (1440 one-minute snapshots:
  every house on its own load shape, its 28 PV on the paper day's BSRN profile, Q = 0) as
  one batched power flow, against OpenDSS's daily mode over the same day (the loads on
  their shapes, each PV a PVSystem on an irradiance shape of the same profile);
  `eulv_day_ratio` = OpenDSS / ours (the issue asks ≥ 10); `eulv_day_dv_pu` the largest
  node |ΔV| between the two at the day's last step (a check that both solved the same day);
- `eulv_volt_var_day_ms`: the closed-loop Volt-VAR day (every snapshot settled), and
  `eulv_volt_var_ratio` = it / the no-action day's (`eulv_no_action_day_ms`) (≤ 3 asked);
- `ieee8500_pf_ms`: one snapshot of the 8500-node feeder (its own loads), the factorization
  included (a fresh network object), and `ieee8500_batch96_ms`: 96 snapshots (the loads ×
  the paper day's load profile every 15 min) in one call, factorization included (≤ 500
  and ≤ 10 000 ms asked);
- `ieee123_sdp_compile_ms`: the SDP relaxation (`formulations.three_phase.bound`) on
  `ieee123` with PV on every second load, built and compiled once (its first solve's own
  time excluded); `ieee123_sdp_step_ms`: its median per-step solve over `SDP_STEPS`
  snapshots (≤ 60 000 and ≤ 2000 asked), `ieee123_sdp_optimal` how many ended optimal, and
  `ieee123_sdp_vs_ac_ratio` = that median / the AC OPF's median per step
  (`formulations.three_phase.optimum`, IPOPT's own time) on the same snapshots;
- the three-phase AC OPF's and LinDist3Flow's keys (`ieee123_opf_…`, `eulv_opf_…`,
  `…_lindist3flow_…`): `bench.unbalanced_opf`;
- with `--large` (`python -m opfbench.bench unbalanced --large [--json]`; `bench all`
  passes it): also one AC OPF solve on `ieee8500` (`ieee8500_opf_…`,
  `bench.unbalanced_opf.ieee8500`), which takes tens of seconds and so is left out without it.

Each time is the best of `REPEATS` calls (ms). Wall-clock figures: re-take them on a quiet
machine.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from opfbench.timing import best_ms

REPEATS = 3


def _eulv_day():
    from opfbench.io import load_case
    from opfbench.study.task_scenarios import chunk_scenario, study_period

    period, _ = study_period(("eulv",), ("off",), "paper-day", "20:00-05:00", None)
    n = len(period.index)
    scenario = chunk_scenario("eulv", "connected", "off", period.profiles, period.night, n, period.index[1] - period.index[0], "")
    return load_case("eulv"), scenario, period.profiles["pv"].to_numpy()[:n]


def _dss_daily(case, scenario, pv_pu: np.ndarray) -> tuple[float, np.ndarray]:
    """OpenDSS's daily mode over the day: (best ms, node |V| p.u. at the last step)."""
    import opendssdirect as dss

    from opfbench.cases.opendss_cases import opendss_copy

    net = case.network
    run = dss.Text.Command
    dss.Basic.AllowChangeDir(False)  # the copy's folder goes away after the compile
    with opendss_copy("eulv") as master:
        run("clear")
        run(f'compile "{master}"')
    i = dss.Loads.First()
    while i:
        dss.Loads.Daily(dss.Loads.Yearly())
        i = dss.Loads.Next()
    mult = " ".join(repr(float(x)) for x in pv_pu)
    run(f"new loadshape.pv npts={len(pv_pu)} minterval=1 mult=[{mult}]")
    db = net.der_branches
    for d, der in enumerate(net.ders):
        node = int(db.a[np.flatnonzero(db.owner == d)[0]])
        bus1 = f"{net.bus_names[der.bus]}.{net.node_phase[node]}"
        kv = float(net.bus_kv_ln[der.bus])
        run(
            f"new pvsystem.pv{d} phases=1 bus1={bus1} kv={kv!r} kva={der.s_rated_mva * 1e3!r} pmpp={der.rating_mw * 1e3!r} "
            "irradiance=1 daily=pv %cutin=0 %cutout=0 vminpu=0.05 vmaxpu=2"
        )

    def day() -> None:
        run("set mode=daily stepsize=1m number=1440 hour=0 sec=0 tolerance=1e-10")
        dss.Solution.Solve()

    ms, _ = best_ms(day, REPEATS)
    return ms, np.asarray(dss.Circuit.AllBusMagPu())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--large", action="store_true", help="also time one AC OPF solve on ieee8500 (tens of seconds)")


def run(args: argparse.Namespace | None = None) -> dict:
    from opfbench.bench import unbalanced_opf
    from opfbench.io import load_case
    from opfbench.multiphase import PhaseNetwork
    from opfbench.powerflow.multiphase import solve_phase_flow
    from opfbench.registry.catalog import run_strategy

    case, scenario, pv_pu = _eulv_day()
    net = case.network
    n_der = len(net.ders)
    load_p, load_q = scenario.element_loads()

    def ours():
        return solve_phase_flow(net, load_p, load_q, scenario.der_p_mw, np.zeros((scenario.n_snapshots, n_der)))

    day_ms, flow = best_ms(ours, REPEATS)
    dss_ms, dss_vm = _dss_daily(case, scenario, pv_pu)
    no_action_ms, _ = best_ms(lambda: run_strategy("no-action", scenario, 0.0), REPEATS)
    volt_var_ms, settled = best_ms(lambda: run_strategy("volt-var", scenario, 0.0), REPEATS)
    big = load_case("ieee8500")
    assert big.stored is not None and isinstance(big.network, PhaseNetwork)
    p, q, der_p, der_q = big.stored

    def fresh():  # a new network object: its factorization is built inside the timed call
        return dataclasses.replace(big.network)

    pf_ms, _ = best_ms(lambda: solve_phase_flow(fresh(), p[None], q[None], der_p[None], der_q[None]), REPEATS)
    profile = _load_profile96()
    batch_ms, batch = best_ms(
        lambda: solve_phase_flow(
            fresh(), profile[:, None] * p, profile[:, None] * q, np.repeat(der_p[None], 96, 0), np.repeat(der_q[None], 96, 0)
        ),
        REPEATS,
    )
    return unbalanced_opf.run() | {
        "eulv_snapshots": int(scenario.n_snapshots),
        "eulv_day_ms": day_ms,
        "eulv_dss_daily_ms": dss_ms,
        "eulv_day_ratio": dss_ms / day_ms,
        "eulv_day_converged": int(np.count_nonzero(flow.converged)),
        "eulv_day_dv_pu": float(np.abs(flow.node_vm_pu[-1] - dss_vm).max()),
        "eulv_no_action_day_ms": no_action_ms,
        "eulv_volt_var_day_ms": volt_var_ms,
        "eulv_volt_var_ratio": volt_var_ms / no_action_ms,
        "eulv_volt_var_not_ok": int(np.count_nonzero(settled.status != "ok")),
        "ieee8500_nodes": int(big.network.n_node),
        "ieee8500_pf_ms": pf_ms,
        "ieee8500_batch96_ms": batch_ms,
        "ieee8500_batch96_converged": int(np.count_nonzero(batch.converged)),
        **_ieee123_sdp(),
        **(unbalanced_opf.ieee8500() if args is not None and args.large else {}),
    }


SDP_STEPS = ((0.9, 1.0), (1.0, 0.6), (1.1, 0.3))
"""(load multiplier, PV irradiance) of the SDP benchmark's snapshots."""


def _ieee123_sdp() -> dict:
    import tempfile
    from pathlib import Path

    from opfbench.cases.opendss_cases import opendss_copy
    from opfbench.cases.opendss_pv import case_with_pv
    from opfbench.formulations.three_phase import bound, optimum
    from opfbench.multiphase import PhaseNetwork

    with tempfile.TemporaryDirectory() as tmp, opendss_copy("ieee123") as master:
        case = case_with_pv(Path(tmp), master, "ieee123")
    assert case.stored is not None and isinstance(case.network, PhaseNetwork)
    lp, lq, dp, _ = case.stored
    mult = np.array([s[0] for s in SDP_STEPS])[:, None]
    sun = np.array([s[1] for s in SDP_STEPS])[:, None]
    relaxed = bound(case.network, lp * mult, lq * mult, dp * sun, 0.0)
    exact = optimum(case.network, lp * mult, lq * mult, dp * sun, 0.0)
    step = float(np.median(relaxed.solve_ms))
    return {
        "ieee123_sdp_compile_ms": relaxed.compile_ms,
        "ieee123_sdp_step_ms": step,
        "ieee123_sdp_optimal": int(np.count_nonzero(relaxed.status == "optimal")),
        "ieee123_sdp_vs_ac_ratio": step / float(np.median(exact.solve_ms)),
    }


def _load_profile96() -> np.ndarray:
    """The paper day's load profile every 15 minutes (96 values, p.u.)."""
    from opfbench.study.periods import resolve_period

    return resolve_period("paper-day", "20:00-05:00").profiles["load"].to_numpy()[::15]


def print_table(figures: dict) -> None:
    for key, value in figures.items():
        print(f"{key:28s} {value:.4g}" if isinstance(value, float) else f"{key:28s} {value}")
