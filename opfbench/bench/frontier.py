"""Sub-benchmark: the frontier of losses against compliance (`formulations.frontier`) against
the plain AC OPF over the same period, in one process.

    python -m opfbench.bench frontier [--json] [--case SPEC] [--period P] [--k K] [--repeats N]

Per case and period (default: paper33 over the paper day, where the band never binds the
optimum, and 1-MV-rural over 2016-04-11..2016-04-18 at 15 min, where it binds at most
daytime steps): `acopf_ms` the `acopf` strategy over the period; `frontier_ms` the
frontier with its own point at ε = 0; `frontier_extra_ms` the frontier given `acopf`'s
answer (what a run pays beyond its acopf rows); `frontier_ratio` = frontier_ms / acopf_ms
(target ≤ TARGET_RATIO) and `frontier_extra_ratio`. Medians of `repeats` timings, each
after the relaxations' solve cache is emptied (every solve timed) and with the compiled
programs of every band already built (a run builds them once per process); single-
threaded BLAS. `binding_steps`: the steps whose band binds the ε = 0 optimum, solved
again; `solves_per_binding_step`: the frontier's solves beyond ε = 0 per such step.
"""

from __future__ import annotations

import argparse
import statistics
from typing import Callable, TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

from opfbench.formulations.frontier import frontier
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.formulations.solves import forget_solves
from opfbench.scenario import Scenario
from opfbench.timing import elapsed_ms, now

TARGET_RATIO = 2.0
DEFAULTS = (("paper33", "paper-day"), ("simbench:1-MV-rural--0-sw", "2016-04-11..2016-04-18"))
NIGHT = "20:00-05:00"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--case", help="one case spec instead of the defaults (with --period)")
    parser.add_argument("--period", default="paper-day", help="the period of --case (default paper-day)")
    parser.add_argument("--k", type=float, default=0.0, help="reserve coefficient (default 0)")
    parser.add_argument("--repeats", type=int, default=3, help="timings per figure, the median reported (default 3)")


def _scenario(case: str, period: str) -> Scenario:
    from opfbench.study.training_checks import training_scenario

    return training_scenario(case, period, NIGHT)[1]


T = TypeVar("T")


def _timed(run: Callable[[], T], repeats: int) -> tuple[float, T]:
    """Median wall time (ms) of `run()` over `repeats` (≥ 1), each on an empty solve cache,
    and its last answer."""
    times = []
    for _ in range(max(repeats, 1)):
        forget_solves()
        t0 = now()
        out = run()
        times.append(elapsed_ms(t0))
    return statistics.median(times), out


def bench_frontier(case: str, period: str, k: float, repeats: int) -> dict:
    """The figures of the module docstring for one case and period."""
    with threadpool_limits(1):
        scenario = _scenario(case, period)
        frontier(scenario, k)  # build every band's programs once, as a run's worker does
        acopf_ms, zero = _timed(lambda: run_acopf(scenario, k), repeats)
        frontier_ms, _ = _timed(lambda: frontier(scenario, k), repeats)
        extra_ms, front = _timed(lambda: frontier(scenario, k, at_zero=zero), repeats)
    solved = front.solved[:, 1:].sum()
    binding = int(front.solved[:, -1].sum())
    return {
        "case": case,
        "period": period,
        "k": k,
        "steps": scenario.n_snapshots,
        "acopf_ms": acopf_ms,
        "frontier_ms": frontier_ms,
        "frontier_extra_ms": extra_ms,
        "frontier_ratio": frontier_ms / acopf_ms,
        "frontier_extra_ratio": extra_ms / acopf_ms,
        "target_ratio": TARGET_RATIO,
        "binding_steps": binding,
        "solves_per_binding_step": float(solved / binding) if binding else 0.0,
        "energy_kwh_by_eps": {
            f"{e:g}": float(np.nansum(c)) * _step_h(period) for e, c in zip(front.eps, front.cost_kw.T, strict=True)
        },
    }


def _step_h(period: str) -> float:
    from opfbench.study.periods import resolve_period

    return resolve_period(period, NIGHT).step_h


def run(args: argparse.Namespace) -> dict:
    pairs = ((args.case, args.period),) if args.case else DEFAULTS
    return {"repeats": args.repeats, "cases": [bench_frontier(case, period, args.k, args.repeats) for case, period in pairs]}


def print_table(f: dict) -> None:
    for c in f["cases"]:
        print(
            f"{c['case']} over {c['period']} ({c['steps']} steps, k={c['k']:g}): acopf {c['acopf_ms']:.0f} ms, "
            f"frontier {c['frontier_ms']:.0f} ms ({c['frontier_ratio']:.2f}×; target ≤ {c['target_ratio']:g}×), "
            f"beyond acopf's answer {c['frontier_extra_ms']:.0f} ms ({c['frontier_extra_ratio']:.2f}×); "
            f"{c['binding_steps']} steps where the band binds, {c['solves_per_binding_step']:.2f} solves each"
        )
        print("  energy by ε (kWh): " + ", ".join(f"{e}: {v:.2f}" for e, v in c["energy_kwh_by_eps"].items()))
