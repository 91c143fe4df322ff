"""`opfbench snapshot CASE --strategy S`: one operating point under one strategy."""

from __future__ import annotations

import argparse

from opfbench.commands.arguments import (
    CASE_HELP,
    add_case_options,
    add_operating_point,
    add_plugin_option,
    case_spec,
    fraction,
    print_json,
    share,
    strategy_labels,
)
from opfbench.errors import InputError
from opfbench.formulations.acopf_options import ACOPF_SOLVERS, FALLBACKS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("snapshot", help="run one strategy on one operating point")
    p.add_argument("case", help=CASE_HELP)
    add_case_options(p)
    p.add_argument(
        "--strategy",
        required=True,
        metavar="LABEL",
        help="a strategy configuration NAME or NAME:key=value,… (e.g. volt-var:curve=a); `opfbench strategies` lists them",
    )
    add_plugin_option(p)
    p.add_argument("--k", type=fraction, default=0.0, help="reactive reserve coefficient in [0, 1] (default 0)")
    add_operating_point(p)
    p.add_argument(
        "--forecast-der-scale",
        type=share,
        default=None,
        help="forecast DER output as a fraction of rating: turns on Algorithm 3 (local rules)",
    )
    p.add_argument(
        "--safe",
        action="store_true",
        help="Algorithm 3: clip setpoints to the physical capability at the current P (local rules)",
    )
    p.add_argument(
        "--fallback",
        choices=FALLBACKS,
        default=None,
        help="AC OPF failure policy: chain (default) or paper (fall back to no action)",
    )
    p.add_argument(
        "--acopf-solver",
        choices=ACOPF_SOLVERS,
        default=None,
        help="AC OPF: auto (default: SOCP-certified fast path, IPOPT for the rest) or ipopt (always)",
    )
    p.add_argument(
        "--no-slack-export", action="store_true", help="formulations: forbid reverse power flow at the slack (slack P ≥ 0)"
    )
    p.set_defaults(func=run)


def _options(args: argparse.Namespace, label: str) -> dict:
    """The strategy options the flags set; a flag the strategy does not take is an error
    (which strategies take it is the registry's word)."""
    from opfbench.registry.catalog import configuration, specs

    spec = configuration(label).spec
    given = {
        "--safe": ("safe", True) if args.safe else None,
        "--fallback": ("fallback", args.fallback) if args.fallback is not None else None,
        "--no-slack-export": ("slack_export", False) if args.no_slack_export else None,
        "--acopf-solver": ("solver", args.acopf_solver) if args.acopf_solver is not None else None,
    }
    options = {}
    for flag, option in given.items():
        if option is None:
            continue
        if option[0] not in spec.option:
            takers = [s.name for s in specs() if option[0] in s.option]
            raise InputError(f"{flag} applies to {', '.join(takers)}, not to {args.strategy}")
        options[option[0]] = option[1]
    if args.forecast_der_scale is not None and not spec.uses_forecast:
        takers = [s.name for s in specs() if s.uses_forecast]
        raise InputError(f"--forecast-der-scale applies to {', '.join(takers)}, not to {args.strategy}")
    return options


def run(args: argparse.Namespace) -> int:
    from opfbench.io import load_case
    from opfbench.multiphase import PhaseNetwork
    from opfbench.registry.catalog import configuration, run_strategy
    from opfbench.scenario import Scenario
    from opfbench.study.training_checks import check_params

    (label,) = strategy_labels([args.strategy], args)
    options = _options(args, label)
    spec = case_spec(args.case, args)
    net = load_case(spec).network
    if isinstance(net, PhaseNetwork):  # a formulation, or a rule without DER, on a three-phase feeder: refused here
        configuration(label).spec.check_network(net)
    check_params([label], [spec])  # a fitted rule runs on the grid it was fitted on (or a perturbed one)
    scenario = Scenario.snapshot(net, args.load_scale, args.der_scale, args.forecast_der_scale)
    result = run_strategy(label, scenario, args.k, **options)
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
        print(
            f"  solver        {out['solver_status']} · {out['iterations']} iterations · {out['solve_ms']:.2f} ms"
            f" · fallback {out['fallback']}"
        )
    print("  Q setpoints   " + ", ".join(f"{name}: {q:+.4f}" for name, q in out["q_mvar"].items()) + " MVAr")
    print(f"  power flows   {out['power_flows']}   excursion {out['excursion_mvar']:.4f} MVAr   wall {out['wall_ms']:.2f} ms")
    for key in result.extra:  # strategy diagnostics, e.g. LFMA's upstream disagreements
        print(f"  {key.replace('_', ' ')}: {out[key]}")
    return 0
