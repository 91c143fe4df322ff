"""The three-phase AC OPF on the unbalanced feeders over the paper's day: the table of
the closing note (`python docs/unbalanced_opf_table.py [--steps N] [CASE …]`, Markdown on
stdout).

Each feeder gets single-phase PV by `opfbench.cases.opendss_pv` (IEEE feeders: on every
second load, P̄ = the load's kW; `eulv`: on every second house, P̄ = 4 kW, as issue 29
states), loads scaled by the paper day's load profile and PV by its PV profile
(`opfbench.data.profiles.paper_day`, N steps evenly over the day), regulator taps held
where the file settles them, k = 0. Per feeder: the statuses, the AC optimum's and no
action's losses summed over the steps where the optimum exists, the steps where no action
leaves the band, and IPOPT's time per step."""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from opfbench.cases.opendss_cases import opendss_copy
from opfbench.cases.opendss_pv import case_with_pv
from opfbench.data.profiles import paper_day
from opfbench.formulations.three_phase import optimum
from opfbench.powerflow.multiphase import solve_phase_flow

PLACEMENT = {"ieee13": {}, "ieee37": {}, "ieee123": {}, "eulv": {"kw": 4.0}}


def row(name: str, steps: int) -> str:
    day = paper_day()
    take = np.linspace(0, len(day) - 1, steps).round().astype(int)
    load, pv = day["load"].to_numpy()[take], day["pv"].to_numpy()[take]
    with tempfile.TemporaryDirectory() as tmp, opendss_copy(name) as master:
        case = case_with_pv(Path(tmp), master, name, **PLACEMENT[name])
    net = case.network
    lp, lq, dp, _ = case.stored
    lp, lq, dp = lp * load[:, None], lq * load[:, None], dp * pv[:, None]
    start = time.perf_counter()
    result = optimum(net, lp, lq, dp, 0.0)
    wall = time.perf_counter() - start
    none = solve_phase_flow(net, lp, lq, dp)
    lo, hi = net.band
    outside = ~((none.vm.min(axis=1) >= lo) & (none.vm.max(axis=1) <= hi))
    found = np.isfinite(result.objective_kw)
    labels = [f"{s} (proven)" if p else s for s, p in zip(result.status.tolist(), result.proven.tolist(), strict=True)]
    counts = ", ".join(f"{s} {n}" for s, n in sorted(Counter(labels).items()))
    return (
        f"| {name} | {len(net.ders)} | {steps} | {counts} | {outside.sum()} | "
        f"{result.losses_kw[found].sum():.3f} | {none.losses_kw[found].sum():.3f} | "
        f"{np.median(result.solve_ms[found]) if found.any() else float('nan'):.0f} | {wall / steps:.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=list(PLACEMENT))
    parser.add_argument("--steps", type=int, default=24)
    args = parser.parse_args()
    print(
        "| feeder | DER | steps | status (steps) | no action outside the band (steps) | AC optimum Σ losses where found (kW·step) "
        "| no action Σ losses there | median IPOPT ms per step | wall s per step |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.cases:
        print(row(name, args.steps), flush=True)


if __name__ == "__main__":
    main()
