"""Sub-benchmark: one learned rule on a year of a SimBench grid at 15 min — the AC OPF over
the training period (the optimum's own cost), the fit, and the closed-loop test over the
rest of the year.

    python -m opfbench.bench learned [--json] [--case SPEC] [--family NAME] [--train START..END] [--test START..END]

Defaults: `simbench:1-MV-rural--0-sw`, `learned-affine`, trained on 2016-01-01..2016-10-01
and tested on 2016-10-01..2017-01-01. `learned_fit_s` = `fit_s` + `test_s`: fitting the
family to the optimum (voltage sensitivity, features, the cvxpy fit) and its closed-loop
evaluation over the test period, wall time in this process with single-threaded BLAS
(target ≤ 300 s on two cores beyond the optimum's cost, `target_learned_fit_s`).
`optimum_s` is the AC OPF over the training period, `reference_s` no action and the AC
OPF over the test period (for the loss-only share the rule reaches, `test_share_pct`, beside
its minutes outside the voltage band, `test_outside_min`). The fit is the run's: with its
compliance refits (`learned.rules`, `comply`), their margins in `comply_margin_pu`.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from functools import lru_cache, partial

import numpy as np
from threadpoolctl import threadpool_limits

from opfbench.formulations.frontier import tightened
from opfbench.learned.rules import FAMILIES, TRAIN_K, VIOLATION_PU, fit_rule, install
from opfbench.registry.catalog import run_strategy
from opfbench.study.training_checks import training_scenario, training_set
from opfbench.timing import elapsed_ms, now

CASE = "simbench:1-MV-rural--0-sw"
TRAIN = "2016-01-01..2016-10-01"
TEST = "2016-10-01..2017-01-01"
NIGHT = "20:00-05:00"
TARGET_LEARNED_FIT_S = 300.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--case", default=CASE, help=f"case spec (default {CASE})")
    parser.add_argument("--family", default="learned-affine", choices=list(FAMILIES))
    parser.add_argument("--train", default=TRAIN, help=f"training period (default {TRAIN})")
    parser.add_argument("--test", default=TEST, help=f"test period (default {TEST})")


def bench_learned(case: str, family: str, train: str, test: str) -> dict:
    """The figures of the module docstring for `family` on `case`."""
    out: dict = {"case": case, "family": family, "train": train, "test": test, "target_learned_fit_s": TARGET_LEARNED_FIT_S}
    with threadpool_limits(1):
        t0 = now()
        _, scenario = training_scenario(case, train, NIGHT)
        optimum = run_strategy("acopf", scenario, TRAIN_K)
        out["optimum_s"] = elapsed_ms(t0) / 1e3
        out["train_steps"] = scenario.n_snapshots
        t0 = now()
        ok = optimum.status == "ok"
        training = training_set(case, train, NIGHT, optimum.q_mvar, ok)
        training = replace(
            training, tightened=lru_cache(partial(tightened, training.scenario, TRAIN_K, q_mvar=optimum.q_mvar, ok=ok))
        )
        params = fit_rule(family, training)
        out["fit_s"] = elapsed_ms(t0) / 1e3
        tried = params.fit["comply"]
        out["comply_margin_pu"] = [t["margin_pu"] for t in tried]
        ref = f"bench:{family}"
        install({ref: params})
        t0 = now()
        test_period, held_out = training_scenario(case, test, NIGHT)
        held_out_step_h = test_period.step_h
        res = run_strategy(f"{family}:params={ref}", held_out, TRAIN_K)
        out["test_s"] = elapsed_ms(t0) / 1e3
        out["test_steps"] = held_out.n_snapshots
        t0 = now()
        base, opf = (run_strategy(name, held_out, TRAIN_K) for name in ("no-action", "acopf"))
        out["reference_s"] = elapsed_ms(t0) / 1e3
    e_base, e_opf, e_rule = (float(np.nansum(r.losses_kw)) for r in (base, opf, res))
    out["learned_fit_s"] = out["fit_s"] + out["test_s"]
    out["test_share_pct"] = 100 * (e_base - e_rule) / (e_base - e_opf) if e_base - e_opf > 0 else float("nan")
    out["not_settled_steps"] = int((res.status == "not-settled").sum())
    out["test_outside_min"] = float((res.voltage_violation() > VIOLATION_PU).sum() * 60 * held_out_step_h)
    out["power_flows_mean"] = float(res.power_flows.mean())
    out["contraction_factor"] = params.fit["contraction_factor"]
    out["params_bytes"] = len(params.text())
    return out


def run(args: argparse.Namespace) -> dict:
    return bench_learned(args.case, args.family, args.train, args.test)


def print_table(f: dict) -> None:
    print(
        f"{f['family']} on {f['case']}: trained on {f['train']} ({f['train_steps']} steps), tested on {f['test']} "
        f"({f['test_steps']} steps)"
    )
    print(f"  the optimum over the training period (AC OPF): {f['optimum_s']:.1f} s (not counted)")
    print(
        f"  fit {f['fit_s']:.2f} s + closed-loop test {f['test_s']:.2f} s = learned_fit_s {f['learned_fit_s']:.1f} s "
        f"(target ≤ {f['target_learned_fit_s']:g} s); {f['power_flows_mean']:.1f} flows per step, "
        f"{f['not_settled_steps']} not settled, contraction factor {f['contraction_factor']:.3f}"
    )
    print(
        f"  loss-only share of the AC OPF's loss reduction on the test period: {f['test_share_pct']:.1f} % "
        f"(not at equal compliance: {f['test_outside_min']:.0f} min outside the voltage band; compliance refits at "
        f"{', '.join(f'{m:g}' for m in f['comply_margin_pu']) or 'none'} p.u.)"
    )
