"""The three-phase AC OPF and its SDP bound on the unbalanced feeders over the paper's day:
the tables of the closing note (`python docs/unbalanced_opf_table.py [--steps N]
[--detail] [CASE …]`, Markdown on stdout; `docs/unbalanced_opf_table.md` is its output).

Each feeder gets single-phase PV by `opfbench.cases.opendss_pv` (IEEE feeders: on every
second load, P̄ = the load's kW; `eulv`: on every second house, P̄ = 4 kW, as issue 29
states), loads scaled by the paper day's load profile and PV by its PV profile
(`opfbench.data.profiles.paper_day`, N steps evenly over the day: night, morning, high PV
at noon, the evening peak), k = 0. Regulator taps (`--taps`): `control` (the default) — the
case option `?taps=control`: per snapshot the taps where the no-action power flow's
controller (OpenDSS's RegControl, static) settles them, held there by the AC OPF, its
confirming power flow and the relaxation (`formulations.three_phase.tap_groups`); a grid
engineer's feeder regulates, and with the file's full-load taps held the band is out of
reach at light load and high PV — or `held`, where OpenDSS settles the file's snapshot.

Per feeder: the AC optimum's statuses (`formulations.three_phase.optimum`), the SDP
relaxation's (`formulations.three_phase.bound`: "optimal" gives a bound; any other status
gives none; its own point: the power flow at its DER Q, `PhaseBound.point_kw` — an
operating point where it meets the band, so the AC optimum should not lie above it), the
AC optimum and the bound summed over the steps where both exist, the
relative gap (AC − bound) / AC there, the steps whose every PSD block is rank one, the
certified share (steps where the AC optimum is within 1e-6 of the bound, or — at a step
without a decision — its power-flow point is proven the only feasible one,
`three_phase.sole_points`, as a run's `certified_by` "unique"; over the steps with an AC
optimum), under tap control the steps whose controller keeps the no-action
taps at the optimum's Q (the power flow under control at its setpoints), and the SDP's
compile (summed over the tap positions: one model each) and per-step times (wall clock:
re-take them on a quiet machine). An AC optimum is a step with status ok or
fallback-cold (a fallback to no action is a point, not an optimum: no gap, no
certificate). `--detail` adds one row per step. `--loads constant-z` solves the same
feeders with every constant-|I| load (OpenDSS model 5) as constant impedance (model 2): a
law the relaxation holds exactly, where it keeps only the hull of a constant-|I| load's
P = P₀·√w (`sdp_three_phase`) — the gap that hull contributes."""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import case_with_pv
from opfbench.data.profiles import paper_day
from opfbench.formulations.three_phase import bound, certify, optimum, q_limits, sole_points
from opfbench.multiphase import PhaseNetwork
from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_Z
from opfbench.powerflow.multiphase import solve_phase_flow
from opfbench.result import FALLBACK_COLD, OK

PLACEMENT = {"ieee13": {}, "ieee37": {}, "ieee123": {}, "eulv": {"kw": 4.0}}


def _counts(labels: list[str]) -> str:
    return ", ".join(f"{s} {n}" for s, n in sorted(Counter(labels).items()))


def snapshots(
    name: str, steps: int, taps: str = "control"
) -> tuple[PhaseNetwork, np.ndarray, np.ndarray, np.ndarray, list[str], np.ndarray, np.ndarray]:
    """The feeder with its PV and regulator taps `taps` (held or control); its loads' P and Q and its PV's P (steps, n) MW/MVAr at
    `steps` times evenly over the paper day; those times ("HH:MM"), and the day's load and
    PV profile values there (p.u.)."""
    day = paper_day()
    take = np.linspace(0, len(day) - 1, steps).round().astype(int)
    load, pv = day["load"].to_numpy()[take], day["pv"].to_numpy()[take]
    with tempfile.TemporaryDirectory() as tmp, opendss_copy(name) as master:
        case = case_with_pv(Path(tmp), master, name, **PLACEMENT[name], taps=taps)
    lp, lq, dp, _ = case.stored
    times = [day.index[t].strftime("%H:%M") for t in take]
    return case.network, lp * load[:, None], lq * load[:, None], dp * pv[:, None], times, load, pv


def constant_z(net: PhaseNetwork) -> PhaseNetwork:
    """`net` with its constant-|I| loads as constant impedance (`--loads constant-z`)."""
    lm = net.load_models
    return dataclasses.replace(
        net, load_models=dataclasses.replace(lm, model=np.where(lm.model == CONSTANT_I, CONSTANT_Z, lm.model))
    )


def feeder(name: str, steps: int, taps: str, loads: str = "as-is") -> tuple[str, list[str]]:
    """The feeder's summary row and its per-step rows."""
    net, lp, lq, dp, times, load, pv = snapshots(name, steps, taps)
    if loads == "constant-z":
        net, name = constant_z(net), f"{name} (constant-I as constant-Z)"
    opt = optimum(net, lp, lq, dp, 0.0)
    start = time.perf_counter()
    relaxed = bound(net, lp, lq, dp, 0.0)
    wall = time.perf_counter() - start
    none = solve_phase_flow(net, lp, lq, dp)
    lo, hi = net.band
    outside = ~((none.vm.min(axis=1) >= lo) & (none.vm.max(axis=1) <= hi))
    has_opt = (opt.status == OK) | (opt.status == FALLBACK_COLD)
    by_sdp, gap = certify(opt, relaxed)
    unique, factor = sole_points(net, lp, lq, dp, q_limits(net, dp, 0.0), opt)
    certified = (by_sdp | unique) & has_opt
    gap = np.where(has_opt, gap, np.nan)
    both = np.isfinite(gap)
    kept = np.full(steps, "", dtype=object)
    if none.tap_positions is not None:  # the controller at the optimum's setpoints: does it keep the taps?
        at_opt = solve_phase_flow(net, lp, lq, dp, opt.q_mvar)
        same = at_opt.converged & (at_opt.tap_positions == none.tap_positions).all(axis=1)
        kept = np.where(has_opt, np.where(same, "yes", "no"), "")
    taps_kept = f"{(kept == 'yes').sum()}/{has_opt.sum()}" if none.tap_positions is not None else "held"
    gaps = f"{np.median(gap[both]):.2e} / {gap[both].max():.2e}" if both.any() else "—"
    share = (
        f"{certified.sum()}/{has_opt.sum()} ({(by_sdp & has_opt).sum()} sdp, {(unique & has_opt).sum()} unique)"
        if has_opt.any()
        else "0/0"
    )
    summary = (
        f"| {name} | {len(net.ders)} | {steps} | {outside.sum()} | {_counts(opt.status.tolist())} | {_counts(relaxed.status.tolist())} | "
        f"{opt.losses_kw[both].sum():.3f} | {relaxed.bound_kw[both].sum():.3f} | {gaps} | "
        f"{relaxed.rank_one.sum()} (max ratio {np.nanmax(relaxed.rank_ratio) if np.isfinite(relaxed.rank_ratio).any() else float('nan'):.1e}) | "
        f"{share} | {taps_kept} | {relaxed.compile_ms / 1e3:.1f} | {np.median(relaxed.solve_ms) / 1e3:.2f} | {wall:.0f} |"
    )
    rows = [
        f"| {name} | {t} | {load[i]:.3f} | {pv[i]:.3f} | {opt.status[i]} | {opt.losses_kw[i]:.4f} | "
        f"{relaxed.status[i]} | {relaxed.bound_kw[i]:.4f} | {gap[i]:.2e} | {relaxed.rank_ratio[i]:.1e} | "
        f"{relaxed.point_kw[i]:.6f} | {(opt.losses_kw[i] - relaxed.point_kw[i]) / opt.losses_kw[i]:.1e} | {_by(by_sdp[i], unique[i], factor[i])} | "
        f"{taps_at(net, none, i)} | {kept[i]} |"
        for i, t in enumerate(times)
    ]
    return summary, rows


def _by(by_sdp: bool, unique: bool, factor: float) -> str:
    """A step's certified column: by which proof, with the contraction factor where one was computed."""
    label = "yes (sdp)" if by_sdp else "yes (unique)" if unique else "no"
    return f"{label}, L = {factor:.3f}" if np.isfinite(factor) else label


def taps_at(net: PhaseNetwork, flow, i: int) -> str:
    """The regulators' taps (p.u.) of snapshot i where the flow's controller settled them."""
    if flow.tap_positions is None:
        return "held"
    return " ".join(f"{reg.taps[p]:.4f}" for reg, p in zip(net.regulators, flow.tap_positions[i].tolist(), strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=list(PLACEMENT))
    parser.add_argument("--steps", type=int, default=24)
    parser.add_argument("--detail", action="store_true", help="one row per step as well")
    parser.add_argument("--taps", choices=("control", "held"), default="control", help="regulator taps (module docstring)")
    parser.add_argument("--loads", choices=("as-is", "constant-z"), default="as-is", help="the loads' models (module docstring)")
    args = parser.parse_args()
    print(
        "| feeder | DER | steps | no action outside the band | AC optimum status (steps) | SDP status (steps) "
        "| Σ AC optimum where both (kW·step) | Σ SDP bound there | gap median / max | rank-one steps "
        "| certified / with an AC optimum | taps kept at the optimum's Q | SDP compile s | median SDP s per step | SDP wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    detail = []
    for name in args.cases:
        summary, rows = feeder(name, args.steps, args.taps, args.loads)
        print(summary, flush=True)
        detail += rows
    if args.detail:
        print(
            "\n| feeder | time | load p.u. | PV p.u. | AC status | AC optimum kW | SDP status | SDP bound kW | gap | rank ratio "
            "| SDP's point kW | (AC − point) / AC | certified | taps (no action's controller) | kept at the optimum's Q |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(detail))


if __name__ == "__main__":
    main()
