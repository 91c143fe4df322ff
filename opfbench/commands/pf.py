"""`opfbench pf CASE`: one AC power flow. A case that stores its elements' operating point
(a pandapower net, a SimBench grid, an OpenDSS feeder's own snapshot) is solved as stored
— loads and generator outputs as in the source — unless --load-scale/--der-scale are given
(then loads × scale and DER at scale × rating, DER Q = 0, as for every other case; an
OpenDSS load of status fixed or exempt keeps its nominal, as under OpenDSS's loadmult);
`--time` takes a step of the case's own profiles (local time).

A three-phase feeder (`opendss:` and the shipped OpenDSS feeders) is solved by the
three-phase power flow (`opfbench.powerflow.multiphase`); its JSON adds `node_vm_pu`
({OpenDSS node name `bus.phase`: |V| in p.u. of the node's base}), the voltage band and
the largest voltage unbalance factor `max_vuf_pct`; `vmin`/`vmax` are over the voltages the
band applies to (`PhaseNetwork.monitored`: phase-to-neutral, phase-to-phase on three-wire
delta sections)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from opfbench.commands.arguments import CASE_HELP, add_case_options, case_spec, fraction, print_json, share
from opfbench.errors import InputError

if TYPE_CHECKING:
    from opfbench.io import Case
    from opfbench.multiphase import PhaseNetwork

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
    from opfbench.multiphase import PhaseNetwork
    from opfbench.powerflow import solve_pf
    from opfbench.scenario import Scenario
    from opfbench.study.periods import local_time

    scaled = args.load_scale is not None or args.der_scale is not None
    if args.time is not None and scaled:
        raise InputError("--time takes loads and DER output from the case's profiles: drop --load-scale/--der-scale")
    case = load_case(case_spec(args.case, args))
    if isinstance(case.network, PhaseNetwork):
        return _three_phase(args, case, case.network)
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


def _three_phase(args: argparse.Namespace, case: Case, net: PhaseNetwork) -> int:
    """`opfbench pf` on a three-phase feeder (module docstring)."""
    from opfbench.powerflow.multiphase import solve_phase_flow

    if args.time is not None:
        raise InputError(f"--time needs a case with its own time series; {args.case!r} has none")
    if args.load_scale is None and args.der_scale is None and case.stored is not None:
        load_p, load_q, der_p, der_q = (np.asarray(x) for x in case.stored)
        point = "stored"
    else:
        load_scale = DEFAULT_LOAD_SCALE if args.load_scale is None else args.load_scale
        der_scale = DEFAULT_DER_SCALE if args.der_scale is None else args.der_scale
        load_p, load_q = (x[0] for x in net.loads_at(load_scale))
        der_p, der_q = np.array([d.rating_mw for d in net.ders]) * der_scale, np.zeros(len(net.ders))
        point = "scaled"
    res = solve_phase_flow(net, load_p[None], load_q[None], der_p[None], der_q[None])
    converged = bool(res.converged[0])
    names = net.monitored[3]
    out: dict = {
        "case": net.name,
        "spec": case.spec,
        "converged": converged,
        "iterations": int(res.iterations[0]),
        "mismatch": float(res.mismatch[0]),
        "operating_point": point,
        "load_scale": None if point == "stored" else (DEFAULT_LOAD_SCALE if args.load_scale is None else args.load_scale),
        "der_scale": None if point == "stored" else (DEFAULT_DER_SCALE if args.der_scale is None else args.der_scale),
        "load_mw": float(load_p.sum()),
        "load_mvar": float(load_q.sum()),
        "der_mw": float(der_p.sum()),
        "der_mvar": float(der_q.sum()),
        "buses": net.n_bus,
        "nodes": net.n_node,
        "band_pu": list(net.band),
        "band": net.band_name,
    }
    figures = ("losses_kw", "vmin", "vmin_at", "vmax", "vmax_at", "outside_band", "max_vuf_pct", "max_vuf_at") + (
        "source_p_mw",
        "source_q_mvar",
        "node_vm_pu",
    )
    if converged:  # a non-converged state has no meaningful losses or voltages
        vm = res.vm[0]
        vuf = res.vuf[0] * 100
        lo, hi = net.band
        three = net.three_phase_nodes
        out |= {
            "losses_kw": float(res.losses_kw[0]),
            "vmin": float(vm.min()),
            "vmin_at": names[int(vm.argmin())],
            "vmax": float(vm.max()),
            "vmax_at": names[int(vm.argmax())],
            "outside_band": int(((vm < lo) | (vm > hi)).sum()),
            "max_vuf_pct": float(vuf.max()) if vuf.size else None,
            "max_vuf_at": net.bus_names[net.node_bus[three[int(vuf.argmax()), 0]]] if vuf.size else None,
            "source_p_mw": float(res.source_kva[0].real / 1e3),
            "source_q_mvar": float(res.source_kva[0].imag / 1e3),
            "node_vm_pu": dict(zip(net.node_names, res.node_vm_pu[0].tolist(), strict=True)),
        }
    else:
        out |= dict.fromkeys(figures)
    if res.tap_positions is not None:  # taps=control: where each regulator settled, p.u. tap
        out["regulator_taps"] = {
            r.name: float(r.taps[p]) for r, p in zip(net.regulators, res.tap_positions[0].tolist(), strict=True)
        }
    out["notes"] = list(case.notes)
    if args.json:
        print_json(out)
    elif converged:
        at = {"stored": "as stored", "scaled": "scaled"}[point]
        print(
            f"{net.name} ({at}, three-phase: {net.n_bus} buses, {net.n_node} nodes): converged in {out['iterations']} iterations"
        )
        print(f"  load    {out['load_mw']:.4f} MW / {out['load_mvar']:.4f} MVAr, DER {out['der_mw']:.4f} MW")
        print(f"  losses  {out['losses_kw']:.3f} kW")
        print(f"  vmin    {out['vmin']:.5f} p.u. at {out['vmin_at']}")
        print(f"  vmax    {out['vmax']:.5f} p.u. at {out['vmax_at']}")
        band = f"{net.band[0]:g}–{net.band[1]:g} p.u. ({net.band_name})"
        print(f"  band    {band}: {out['outside_band']} of {len(names)} voltages outside")
        if out["max_vuf_pct"] is not None:
            print(f"  VUF     {out['max_vuf_pct']:.3f} % at bus {out['max_vuf_at']} (largest)")
        for note in case.notes:
            print(f"  note: {note}")
    else:
        print(f"{net.name}: power flow DID NOT CONVERGE within {out['iterations']} iterations")
    return 0 if converged else 1
