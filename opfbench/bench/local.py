"""Sub-benchmark: the local rules over a day of 1-min snapshots of `paper33`, batched.

The day is synthetic and deterministic (seeded): loads follow a two-peak daily shape,
PV a clear-sky bell from 06:00 to 18:00 dented by random clouds, the DFIG a smooth
random walk. It stands in for the real series until the data pipeline provides them;
only timing and the bookkeeping (statuses, power-flow counts) are the point here.

    python -m opfbench.bench.local [--n 1440] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from opfbench.cases import load_case
from opfbench.registry import LOCAL_RULES, run_strategy
from opfbench.scenario import Scenario

SEED = 20240601


def daily_scenario(case: str = "paper33", n: int = 1440, seed: int = SEED) -> Scenario:
    """n equally spaced snapshots over 24 h (n = 1440: one per minute)."""
    net = load_case(case)
    rng = np.random.default_rng(seed)
    hours = np.arange(n) * 24.0 / n
    load = 0.55 + 0.30 * np.exp(-((hours - 8.0) / 2.0) ** 2) + 0.45 * np.exp(-((hours - 19.0) / 2.5) ** 2)
    sun = np.clip(np.sin(np.pi * (hours - 6.0) / 12.0), 0.0, None)
    clouds = 1.0 - 0.5 * np.clip(np.convolve(rng.standard_normal(n), np.ones(15) / 15, "same"), 0.0, 1.0)
    wind = 0.5 + 0.4 * np.sin(np.cumsum(rng.normal(0.0, 0.02, n)) + 1.0)
    kinds = np.array(net.der_kinds)
    per_unit = np.where(kinds == "PV", (sun * clouds)[:, None], wind[:, None])
    return Scenario(net, load, per_unit * net.der_rating_mw)


def _best_ms(fn, repeats: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, (time.perf_counter() - t0) * 1e3)
    return best, out


def bench_local(n: int = 1440, k: float = 0.4, repeats: int = 3, loop_sample: int = 60) -> dict:
    """Best-of-`repeats` wall time of each local rule over `n` snapshots in one batch, and
    for comparison LFMA run snapshot by snapshot on the first `loop_sample` of them
    (extrapolated to n). Energy losses assume the n snapshots span 24 h."""
    scenario = daily_scenario(n=n)
    out: dict = {"case": scenario.net.name, "snapshots": n, "k": k, "repeats": repeats, "rules": {}}
    for name in LOCAL_RULES:
        ms, res = _best_ms(lambda: run_strategy(name, scenario, k), repeats)
        ok = res.status == "ok"
        out["rules"][name] = {
            "wall_ms": round(ms, 2), "ms_per_snapshot": round(ms / n, 4),
            "power_flows_per_snapshot": int(res.power_flows.max()), "ok": int(ok.sum()),
            "energy_losses_kwh": round(float(np.nansum(res.losses_kw) * 24.0 / n), 3),
        }
    m = min(loop_sample, n)
    if m:
        ms, _ = _best_ms(lambda: [run_strategy("lfma", scenario.take(slice(i, i + 1)), k) for i in range(m)], 1)
        out["lfma_one_by_one_ms_extrapolated"] = round(ms * n / m, 1)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1440)
    parser.add_argument("--k", type=float, default=0.4)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    print(json.dumps(bench_local(args.n, args.k, args.repeats), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
