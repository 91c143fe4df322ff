"""`opfbench snapshot CASE --strategy S`: one operating point under one strategy."""

from __future__ import annotations

import argparse

from opfbench.cases import load_case
from opfbench.commands.common import add_operating_point, fraction, print_json
from opfbench.errors import InputError
from opfbench.registry import FORMULATIONS, LOCAL_RULES, STRATEGY_NAMES, run_strategy
from opfbench.scenario import Scenario


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("snapshot", help="run one strategy on one operating point")
    p.add_argument("case", help="shipped case name (see `opfbench cases`) or path to a MATPOWER .m file")
    p.add_argument("--strategy", required=True, choices=STRATEGY_NAMES)
    p.add_argument("--k", type=fraction, default=0.0, help="reactive reserve coefficient in [0, 1] (default 0)")
    add_operating_point(p)
    p.add_argument("--forecast-der-scale", type=fraction, default=None,
                   help="forecast DER output as a fraction of rating: turns on Algorithm 3 (local rules)")
    p.add_argument("--safe", action="store_true",
                   help="Algorithm 3: clip setpoints to the physical capability at the current P (local rules)")
    p.add_argument("--fallback", choices=("chain", "paper"), default=None,
                   help="AC OPF failure policy: chain (default) or paper (fall back to no action)")
    p.add_argument("--no-slack-export", action="store_true",
                   help="formulations: forbid reverse power flow at the slack (slack P ≥ 0)")
    p.set_defaults(func=run)


def _options(args: argparse.Namespace) -> dict:
    if args.strategy in LOCAL_RULES:
        for flag, given in (("--fallback", args.fallback is not None), ("--no-slack-export", args.no_slack_export)):
            if given:
                raise InputError(f"{flag} applies to the formulations ({', '.join(FORMULATIONS)}), not to {args.strategy}")
        return {"safe": args.safe} if args.strategy != "no-action" else {}
    for flag, given in (("--safe", args.safe), ("--forecast-der-scale", args.forecast_der_scale is not None)):
        if given:
            raise InputError(f"{flag} applies to the local rules ({', '.join(LOCAL_RULES)}), not to {args.strategy}")
    if args.fallback is not None and args.strategy != "acopf":
        raise InputError("--fallback applies to acopf only")
    options = {"slack_export": not args.no_slack_export}
    if args.strategy == "acopf":
        options["fallback"] = args.fallback or "chain"
    return options


def run(args: argparse.Namespace) -> int:
    options = _options(args)
    net = load_case(args.case)
    scenario = Scenario.snapshot(net, args.load_scale, args.der_scale, args.forecast_der_scale)
    result = run_strategy(args.strategy, scenario, args.k, **options)
    out = result.snapshot_json(0)
    if args.json:
        print_json(out)
        return 0
    print(f"{net.name} · {out['strategy']} · k = {out['k']:g} · status {out['status']}")
    losses = "n/a" if out["losses_kw"] is None else f"{out['losses_kw']:.3f} kW"
    print(f"  losses        {losses}")
    if out["vmin"] is not None:
        print(f"  voltages      {out['vmin']:.5f} … {out['vmax']:.5f} p.u.")
    if out.get("lower_bound_kw") is not None:
        print(f"  lower bound   {out['lower_bound_kw']:.3f} kW")
    if "fallback" in out:  # the formulations: how the point was obtained
        print(f"  solver        {out['solver_status']} · {out['iterations']} iterations · {out['solve_ms']:.2f} ms"
              f" · fallback {out['fallback']}")
    print("  Q setpoints   " + ", ".join(f"bus {b}: {q:+.4f}" for b, q in out["q_mvar"].items()) + " MVAr")
    print(f"  power flows   {out['power_flows']}   excursion {out['excursion_mvar']:.4f} MVAr   wall {out['wall_ms']:.2f} ms")
    for key in result.extra:  # strategy diagnostics, e.g. LFMA's upstream disagreements
        print(f"  {key.replace('_', ' ')}: {out[key]}")
    return 0
