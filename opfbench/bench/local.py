"""Sub-benchmark: the built-in local rules over the paper day (1440 × 1 min) on `paper33`,
each rule run as one batch, and LFMA run snapshot by snapshot on a sample for comparison.

    python -m opfbench.bench local [--json]

`voltvar_day_ms` is the closed-loop Volt-VAR day (IEEE 1547 Category B, settled by the
engine's damped iteration) and `voltvar_iterations_mean` the power flows it needs per
snapshot on average (each iteration is one flow, the evaluation included);
`voltvar_vs_lfma` its time over LFMA's day in the same process (target: ≤ 3). Times are CPU
times (`opfbench.timing.best_ms` with `cpu=True`; the rules run single-threaded).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from opfbench.bench.paper_day import paper_day_scenario
from opfbench.powerflow.memo import cold
from opfbench.registry.catalog import run_strategy, specs
from opfbench.scenario import Scenario
from opfbench.timing import best_ms

VOLT_VAR = "volt-var"
TARGET_VOLTVAR_VS_LFMA = 3.0


def bench_local(scenario: Scenario, k: float = 0.4, repeats: int = 3, loop_sample: int = 60) -> dict:
    """Best-of-`repeats` wall time of each built-in local rule over all snapshots of
    `scenario` in one batch, and LFMA run one snapshot at a time on the first `loop_sample`
    snapshots (extrapolated), checking that both give the same setpoints
    (`lfma_one_by_one_max_dq_mvar`). Energy assumes the snapshots are equally spaced over 24 h."""
    n = scenario.n_snapshots
    out: dict = {"case": scenario.net.name, "snapshots": n, "k": k, "repeats": repeats, "rules": {}}
    for spec in specs():
        if spec.kind != "local" or spec.source != "opfbench" or spec.learned:  # learned rules: `bench learned`
            continue
        ms, res = best_ms(partial(cold, run_strategy, spec.name, scenario, k), repeats, cpu=True)
        out["rules"][spec.name] = {
            "wall_ms": ms,
            "ms_per_snapshot": ms / n,
            "power_flows_per_snapshot": int(res.power_flows.max()),
            "power_flows_mean": float(res.power_flows.mean()),
            "ok": int((res.status == "ok").sum()),
            "energy_losses_kwh": float(np.nansum(res.losses_kw) * 24.0 / n),
        }
    m = min(loop_sample, n)
    ms, singles = best_ms(lambda: [run_strategy("lfma", scenario.take(slice(i, i + 1)), k) for i in range(m)], 1, cpu=True)
    batch = run_strategy("lfma", scenario.take(slice(0, m)), k)
    out["lfma_one_by_one_max_dq_mvar"] = float(np.abs(np.concatenate([r.q_mvar for r in singles]) - batch.q_mvar).max())
    out["lfma_one_by_one_ms_extrapolated"] = ms * n / m
    out["ratio_batch_vs_one_by_one"] = out["lfma_one_by_one_ms_extrapolated"] / out["rules"]["lfma"]["wall_ms"]
    out["voltvar_day_ms"] = out["rules"][VOLT_VAR]["wall_ms"]
    out["voltvar_iterations_mean"] = out["rules"][VOLT_VAR]["power_flows_mean"]
    out["voltvar_vs_lfma"] = out["voltvar_day_ms"] / out["rules"]["lfma"]["wall_ms"]
    out["target_voltvar_vs_lfma"] = TARGET_VOLTVAR_VS_LFMA
    return out


def run() -> dict:
    return bench_local(paper_day_scenario("paper33"))


def print_table(f: dict) -> None:
    print(f"local rules on {f['case']}, {f['snapshots']} snapshots of the paper day, k = {f['k']}")
    for name, r in f["rules"].items():
        print(
            f"  {name:<10} {r['wall_ms']:8.1f} ms  ({r['ms_per_snapshot']:.3f} ms/snapshot, "
            f"{r['power_flows_mean']:.2f} flows/snapshot (max {r['power_flows_per_snapshot']}), {r['ok']} ok, "
            f"{r['energy_losses_kwh']:.2f} kWh)"
        )
    print(
        f"  LFMA one snapshot at a time (extrapolated): {f['lfma_one_by_one_ms_extrapolated']:.0f} ms "
        f"→ batching is {f['ratio_batch_vs_one_by_one']:.1f}× faster (same setpoints to {f['lfma_one_by_one_max_dq_mvar']:.1e} MVAr)"
    )
    print(
        f"  closed-loop Volt-VAR day: {f['voltvar_day_ms']:.1f} ms, {f['voltvar_iterations_mean']:.2f} flows per snapshot; "
        f"{f['voltvar_vs_lfma']:.2f}× LFMA's day (target ≤ {f['target_voltvar_vs_lfma']:g}×)"
    )
