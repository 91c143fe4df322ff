"""`opfbench pf CASE`: one AC power flow at a load/DER scaling (DER Q = 0)."""

from __future__ import annotations

import argparse

from opfbench.commands.common import add_operating_point, print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("pf", help="AC power flow (Newton–Raphson) on a case")
    p.add_argument("case", help="shipped case name (see `opfbench cases`) or path to a MATPOWER .m file")
    add_operating_point(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.cases import load_case
    from opfbench.powerflow import bus_injections, solve_pf

    net = load_case(args.case)
    res = solve_pf(net, bus_injections(net, args.der_scale * net.der_rating_mw, 0.0, args.load_scale))
    out = {
        "case": net.name,
        "converged": bool(res.converged),
        "iterations": int(res.iterations),
        "load_scale": args.load_scale,
        "der_scale": args.der_scale,
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
    if args.json:
        print_json(out)
    elif res.converged:
        print(f"{net.name}: converged in {out['iterations']} iterations")
        print(f"  losses  {out['losses_kw']:.3f} kW")
        print(f"  vmin    {out['vmin']:.5f} p.u. at bus {out['vmin_bus']}")
        print(f"  vmax    {out['vmax']:.5f} p.u. at bus {out['vmax_bus']}")
    else:
        print(f"{net.name}: power flow DID NOT CONVERGE within {out['iterations']} Newton iterations")
    return 0 if res.converged else 1
