"""Sub-benchmark: the local rules over the paper day (1440 × 1 min) on `paper33`, each
rule run as one batch, and LFMA run snapshot by snapshot on a sample for comparison.

    python -m opfbench.bench local [--json]
"""

from __future__ import annotations

from functools import partial

import numpy as np

from opfbench.bench.profiles import paper_day_scenario
from opfbench.registry import LOCAL_RULES, run_strategy
from opfbench.scenario import Scenario
from opfbench.timing import best_ms


def bench_local(scenario: Scenario, k: float = 0.4, repeats: int = 3, loop_sample: int = 60) -> dict:
    """Best-of-`repeats` wall time of each local rule over all snapshots of `scenario` in
    one batch, and LFMA run one snapshot at a time on the first `loop_sample` snapshots
    (extrapolated), checking that both give the same setpoints (`lfma_one_by_one_max_dq_mvar`).
    Energy assumes the snapshots are equally spaced over 24 h."""
    n = scenario.n_snapshots
    out: dict = {"case": scenario.net.name, "snapshots": n, "k": k, "repeats": repeats, "rules": {}}
    for name in LOCAL_RULES:
        ms, res = best_ms(partial(run_strategy, name, scenario, k), repeats)
        out["rules"][name] = {
            "wall_ms": ms,
            "ms_per_snapshot": ms / n,
            "power_flows_per_snapshot": int(res.power_flows.max()),
            "ok": int((res.status == "ok").sum()),
            "energy_losses_kwh": float(np.nansum(res.losses_kw) * 24.0 / n),
        }
    m = min(loop_sample, n)
    ms, singles = best_ms(lambda: [run_strategy("lfma", scenario.take(slice(i, i + 1)), k) for i in range(m)], 1)
    batch = run_strategy("lfma", scenario.take(slice(0, m)), k)
    out["lfma_one_by_one_max_dq_mvar"] = float(np.abs(np.concatenate([r.q_mvar for r in singles]) - batch.q_mvar).max())
    out["lfma_one_by_one_ms_extrapolated"] = ms * n / m
    out["ratio_batch_vs_one_by_one"] = out["lfma_one_by_one_ms_extrapolated"] / out["rules"]["lfma"]["wall_ms"]
    return out


def run() -> dict:
    return bench_local(paper_day_scenario("paper33"))


def print_table(f: dict) -> None:
    print(f"local rules on {f['case']}, {f['snapshots']} snapshots of the paper day, k = {f['k']}")
    for name, r in f["rules"].items():
        print(
            f"  {name:<10} {r['wall_ms']:8.1f} ms  ({r['ms_per_snapshot']:.3f} ms/snapshot, "
            f"{r['power_flows_per_snapshot']} flows/snapshot, {r['ok']} ok, {r['energy_losses_kwh']:.2f} kWh)"
        )
    print(
        f"  LFMA one snapshot at a time (extrapolated): {f['lfma_one_by_one_ms_extrapolated']:.0f} ms "
        f"→ batching is {f['ratio_batch_vs_one_by_one']:.1f}× faster (same setpoints to {f['lfma_one_by_one_max_dq_mvar']:.1e} MVAr)"
    )
