"""`opfbench fault CASE --fault-bus B|all`: the fault ride-through study (RMS simulation,
Danish grid-code reactive current, recovery time per bus × strategy × k × forecast ×
model variant). See `opfbench.dynamics`."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from typing import TYPE_CHECKING

from opfbench.capability import PAPER_KS
from opfbench.commands.arguments import (
    CASE_HELP,
    STRATEGY_HELP,
    add_case_options,
    add_execution_options,
    add_plugin_option,
    case_spec,
    fraction,
    number,
    path,
    share,
    strategy_labels,
)
from opfbench.dynamics.params import FORECASTS, SENSITIVITY_VARIANTS, FaultParams, ModelParams
from opfbench.errors import InputError
from opfbench.jsonio import print_json
from opfbench.registry.references import DEFAULT_FAULT

if TYPE_CHECKING:
    from opfbench.io.case import Case


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fault", help="fault ride-through study: recovery times per bus × strategy × k")
    p.add_argument("case", help=CASE_HELP)
    add_case_options(p)
    p.add_argument("--fault-bus", nargs="+", required=True, help="bus number(s) to fault, or 'all'")
    p.add_argument("--fault-impedance", type=number, default=0.02, help="fault reactance, p.u. (default 0.02)")
    p.add_argument("--duration-ms", type=number, default=150.0, help="fault duration, ms (default 150)")
    p.add_argument("--strategies", nargs="+", default=list(DEFAULT_FAULT), metavar="LABEL", help=STRATEGY_HELP)
    add_plugin_option(p)
    p.add_argument("--k", nargs="+", type=fraction, default=list(PAPER_KS), help="reserve coefficients")
    p.add_argument(
        "--forecast",
        nargs="+",
        choices=FORECASTS,
        default=["off"],
        help="setpoints without (off) and with the oracle forecast (Algorithm 3)",
    )
    p.add_argument("--load-scale", type=fraction, default=1.0, help="multiplier on the nominal loads (default 1)")
    p.add_argument("--der-scale", type=share, default=0.8, help="DER output as a fraction of rating (default 0.8)")
    p.add_argument(
        "--time",
        default=None,
        help="HH:MM: the paper day's minute as operating point instead; on a case with its own profiles "
        "(simbench:CODE) a local date and time, e.g. 2016-11-08T12:00",
    )
    p.add_argument("--motor-share", type=number, default=0.5, help="share of each load's P in motors, 0..1")
    p.add_argument("--motor-inertia", type=number, default=0.2, help="motor H, s (default 0.2)")
    p.add_argument("--torque", choices=("quadratic", "constant"), default="quadratic", help="motor load torque law")
    p.add_argument(
        "--source-impedance",
        type=number,
        default=None,
        help="upstream source reactance, p.u. (default 0.2; a case with its upstream grid's short-circuit data — "
        "pandapower's ext_grid s_sc_max_mva/rx_max, SimBench's CIGRE values — takes R and X from it)",
    )
    p.add_argument(
        "--emf",
        type=number,
        default=None,
        help="source EMF |E| in p.u. (default: re-set so the slack sits at its scheduled voltage)",
    )
    p.add_argument(
        "--active",
        choices=("constant-power", "ramp"),
        default="constant-power",
        help="inverter active power after the dip (default constant-power)",
    )
    p.add_argument("--area-c-trip", action="store_true", help="inverters disconnect below 0.2 p.u. (area C)")
    p.add_argument(
        "--variants",
        nargs="+",
        default=None,
        help="model variants key=value[,key=value] (emf=held, source=0.1, motors=0.3, inertia=H, "
        "torque=constant, active=ramp, emf-pu=E; each key once) or 'reference' (default: reference)",
    )
    p.add_argument("--sensitivity", action="store_true", help="run the sensitivity variants: " + " ".join(SENSITIVITY_VARIANTS))
    p.add_argument("--t-end", type=number, default=3.0, help="simulated time, s (default 3)")
    p.add_argument("--step-ms", type=number, default=1.0, help="fixed step, ms (default 1)")
    add_execution_options(p, default_workers=1)  # a local cluster's start-up outweighs a small study's work
    p.add_argument(
        "--out",
        type=path,
        default=None,
        help="the study's folder: fault.parquet, traces.parquet, manifest.json and its checkpoints (tasks/), "
        "resumable (default: a temporary folder, removed afterwards)",
    )
    p.add_argument("--json", action="store_true", help="print a list, one record per simulation")
    p.set_defaults(func=run)


def _params(args: argparse.Namespace, case: Case) -> ModelParams:
    from opfbench.dynamics.point import case_source

    base = ModelParams() if args.source_impedance is not None else case_source(case, ModelParams())
    impedance = base.source.impedance_pu if args.source_impedance is None else args.source_impedance
    src = replace(base.source, impedance_pu=impedance, emf="reset" if args.emf is None else "given", emf_pu=args.emf)
    mot = replace(base.motors, share=args.motor_share, h_s=args.motor_inertia, torque=args.torque)
    inv = replace(base.inverters, active=args.active, area_c_trip=args.area_c_trip)
    params = ModelParams(src, mot, inv)
    params.check()
    return params


def _buses(args: argparse.Namespace, net) -> tuple[int, ...]:
    if args.fault_bus == ["all"]:
        return tuple(int(b) for b in net.bus_ids)
    try:
        return tuple(int(b) for b in args.fault_bus)
    except ValueError:
        raise InputError(f"--fault-bus takes bus numbers or 'all', got {' '.join(args.fault_bus)}") from None


def _variants(args: argparse.Namespace) -> tuple[str, ...]:
    """--sensitivity's variants, then those of --variants not among them (default: reference)."""
    given = tuple(args.variants or (() if args.sensitivity else ("reference",)))
    if not args.sensitivity:
        return given
    return SENSITIVITY_VARIANTS + tuple(v for v in given if v not in SENSITIVITY_VARIANTS)


def run(args: argparse.Namespace) -> int:
    from opfbench.commands.progress import console
    from opfbench.dynamics.study import FaultConfig, run_fault_study  # numba: only when a study runs
    from opfbench.io import load_case
    from opfbench.study.training_checks import check_params

    case = load_case(case_spec(args.case, args))
    net = case.balanced("the fault study (a balanced three-phase RMS model)")
    if args.duration_ms < 0:
        raise InputError(f"--duration-ms must be ≥ 0, got {args.duration_ms:g}")
    if args.fault_impedance < 0:
        raise InputError(f"--fault-impedance must be ≥ 0, got {args.fault_impedance:g}")
    if args.step_ms <= 0:
        raise InputError(f"--step-ms must be > 0, got {args.step_ms:g}")
    if args.time is not None and (args.load_scale != 1.0 or args.der_scale != 0.8):
        raise InputError("--time takes loads and DER output from the paper day: drop --load-scale/--der-scale")
    fault = FaultParams(
        bus=0, impedance_pu=args.fault_impedance, duration_s=args.duration_ms / 1e3, t_end_s=args.t_end, step_s=args.step_ms / 1e3
    )
    config = FaultConfig.build(
        case=case.spec,
        fault_buses=_buses(args, net),
        strategies=strategy_labels(args.strategies, args),
        ks=args.k,
        forecasts=args.forecast,
        variants=_variants(args),
        params=_params(args, case),
        fault=fault,
        load_scale=args.load_scale,
        der_scale=args.der_scale,
        time=args.time,
    )
    config.check(net)  # before any work
    check_params(config.strategies, [case.spec])
    try:
        study = run_fault_study(
            config,
            case,
            args.out,
            workers=args.workers,
            scheduler=args.scheduler,
            fresh=args.fresh,
            command=["opfbench", "fault", *sys.argv[2:]],
            reporter=console(args.quiet or args.json),
        )
    except MemoryError:
        raise InputError(
            "out of memory: the study's simulations and traces do not fit in this machine's memory; lengthen the step "
            "(--step-ms), shorten the simulated time (--t-end), or fault fewer buses (--fault-bus) in fewer variants"
        ) from None
    if args.json:
        from opfbench.dynamics.study import simulation_records

        print_json(simulation_records(study.table, net.bus_ids))
        return 0
    _print_table(study.table, net, study.family.point.label, study.timings)
    if args.out is not None:
        print(f"wrote {args.out}/fault.parquet, traces.parquet, manifest.json")
    return 0


def _print_table(table, net, label: str, timings: dict) -> None:
    from opfbench.dynamics.recovery import recovery_table

    print(f"{net.name} · {label} · {timings['simulations']} simulations in {timings['study_s']:.1f} s")
    print(
        f"{'variant':<12} {'fault':>5} {'strategy':<10} {'k':>4} {'fc':<6} {'status':<13} "
        f"{'rec@fault ms':>12} {'slowest ms':>10} {'at bus':>6} {'margin':>8} {'stalled':>7}"
    )
    print(
        "(recovery: ms from inception until |V| ≥ 0.9 p.u. for good, nan = not recovered; margin: min |V| − 0.9 "
        "p.u. over the last 100 ms at the slowest bus)"
    )
    for r in recovery_table(table).itertuples(index=False):
        print(
            f"{r.variant:<12} {r.fault_bus:>5} {r.strategy:<10} {r.k:>4.1f} {r.forecast:<6} {r.feeder_status:<13} "
            f"{r.recovery_ms:>12.1f} {r.feeder_recovery_ms:>10.1f} {r.slowest_bus:>6} {r.slowest_margin_pu:>8.4f} "
            f"{r.motors_stalled:>7}"
        )
