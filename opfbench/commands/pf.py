"""`opfbench pf CASE`: one AC power flow. A case that stores its elements' operating point
(a pandapower net, a SimBench grid) is solved as stored — loads and generator outputs as
in the net — unless --load-scale/--der-scale are given (then loads × scale and DER at
scale × rating, DER Q = 0, as for every other case); `--time` takes a step of the case's
own profiles (local time)."""

from __future__ import annotations

import argparse

import numpy as np

from opfbench.commands.arguments import CASE_HELP, add_case_options, case_spec, fraction, print_json, share
from opfbench.errors import InputError

DEFAULT_LOAD_SCALE, DEFAULT_DER_SCALE = 1.0, 0.8


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("pf", help="AC power flow (Newton–Raphson) on a case")
    p.add_argument("case", help=CASE_HELP)
    add_case_options(p)
    p.add_argument(
        "--load-scale",
        type=fraction,
        default=None,
        help=f"multiplier on every nominal load (default {DEFAULT_LOAD_SCALE}; a stored net: its stored loads)",
    )
    p.add_argument(
        "--der-scale",
        type=share,
        default=None,
        help=f"DER active power as a fraction of rating, 0..1 (default {DEFAULT_DER_SCALE}; a stored net: its stored output)",
    )
    p.add_argument(
        "--time",
        default=None,
        help="a step of the case's own profiles, local time (Europe/Berlin), e.g. 2016-11-08T12:00",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from opfbench.io import load_case
    from opfbench.powerflow import solve_pf
    from opfbench.scenario import Scenario
    from opfbench.study.periods import local_time

    scaled = args.load_scale is not None or args.der_scale is not None
    if args.time is not None and scaled:
        raise InputError("--time takes loads and DER output from the case's profiles: drop --load-scale/--der-scale")
    case = load_case(case_spec(args.case, args))
    net = case.network
    der_q = np.zeros(len(net.ders))
    when = None
    if args.time is not None:
        if case.series is None:
            raise InputError(f"--time needs a case with its own time series (simbench:CODE); {args.case!r} has none")
        when = local_time(args.time, "--time")
        scenario, point = Scenario.of_case(case, pd.DatetimeIndex([when])), "profile"
    elif case.stored is not None and not scaled:
        scenario, point = Scenario.of_case(case), "stored"
        der_q = case.stored[3]
    else:
        load_scale = DEFAULT_LOAD_SCALE if args.load_scale is None else args.load_scale
        der_scale = DEFAULT_DER_SCALE if args.der_scale is None else args.der_scale
        scenario, point = Scenario.snapshot(net, load_scale, der_scale), "scaled"
    res = solve_pf(net, scenario.injections(der_q[None, :])[0])
    load = scenario.bus_load_mva()[0]
    out = {
        "case": net.name,
        "spec": case.spec,
        "converged": bool(res.converged),
        "iterations": int(res.iterations),
        "operating_point": point,
        "time": None if when is None else when.isoformat(),
        "load_scale": float(scenario.load_scale[0]) if scenario.load_scale is not None else None,
        "der_scale": (DEFAULT_DER_SCALE if args.der_scale is None else args.der_scale) if point == "scaled" else None,
        "load_mw": float(load.real.sum()),
        "load_mvar": float(load.imag.sum()),
        "der_mw": float(scenario.der_p_mw[0].sum()),
        "der_mvar": float(der_q.sum()),
    }
    if res.converged:  # a non-converged state has no meaningful losses or voltages
        vmin, vmin_bus = res.extreme_voltage("min")
        vmax, vmax_bus = res.extreme_voltage("max")
        out |= {
            "losses_kw": float(res.losses_kw),
            "vmin": float(vmin),
            "vmin_bus": int(vmin_bus),
            "vmax": float(vmax),
            "vmax_bus": int(vmax_bus),
            "slack_p_mw": float(res.slack_s_mva.real),
            "slack_q_mvar": float(res.slack_s_mva.imag),
        }
    else:
        out |= dict.fromkeys(("losses_kw", "vmin", "vmin_bus", "vmax", "vmax_bus", "slack_p_mw", "slack_q_mvar"))
    out["notes"] = list(case.notes)
    if args.json:
        print_json(out)
    elif res.converged:
        at = {"stored": "as stored", "profile": f"profile step {out['time']}", "scaled": "scaled"}[point]
        print(f"{net.name} ({at}): converged in {out['iterations']} iterations")
        print(f"  load    {out['load_mw']:.4f} MW / {out['load_mvar']:.4f} MVAr, DER {out['der_mw']:.4f} MW")
        print(f"  losses  {out['losses_kw']:.3f} kW")
        print(f"  vmin    {out['vmin']:.5f} p.u. at bus {out['vmin_bus']}")
        print(f"  vmax    {out['vmax']:.5f} p.u. at bus {out['vmax_bus']}")
        for note in case.notes:
            print(f"  note: {note}")
    else:
        print(f"{net.name}: power flow DID NOT CONVERGE within {out['iterations']} Newton iterations")
    return 0 if res.converged else 1
