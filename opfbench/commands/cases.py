"""`opfbench cases [SPEC …]`: the shipped cases — the balanced ones and the unbalanced
OpenDSS feeders — (or the given specs: files, simbench:CODE, opendss:PATH) with
bus/node/branch/DER/load counts; `--simbench` lists the SimBench codes the field suite
runs. The text listing prints each case as it is read (an OpenDSS feeder is compiled on
its first read, then kept on disk: `opfbench.io.disk_cache`)."""

from __future__ import annotations

import argparse

from opfbench.commands.arguments import print_json
from opfbench.io.sources import formats


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cases", help="list the shipped cases (or describe the given case specs)")
    p.add_argument("specs", nargs="*", help="case specs to describe (default: every shipped case)")
    p.add_argument("--simbench", action="store_true", help="describe the field suite's SimBench grids too (slow: ~5 s each)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def _row(spec: str) -> dict:
    from opfbench.io import load_case

    c = load_case(spec)
    summary = c.network.summary()
    profile = c.series.source if c.series is not None else PERIOD_LOADS
    return summary | {
        "spec": c.spec,
        "nodes": summary.get("nodes"),
        "series": c.series is not None,
        "load_profile": profile,
        "notes": list(c.notes),
    }


PERIOD_LOADS = (
    "the period's load profile (SimBench aggregated semi-urban MV load, peak = nominal within the period) × each "
    "load's nominal P and Q"
)
"""What a case without its own series runs on (`opfbench.data.profiles`)."""


def run(args: argparse.Namespace) -> int:
    from opfbench.cases import CASE_NAMES
    from opfbench.cases.opendss_cases import OPENDSS_NAMES
    from opfbench.io.simbench import SUITE

    specs = list(args.specs) or list(CASE_NAMES + OPENDSS_NAMES)
    if args.simbench:
        specs += [f"simbench:{code}" for code in SUITE]
    if args.json:
        print_json([_row(spec) for spec in specs])
        return 0
    print(f"{'case':<28}{'buses':>6}{'nodes':>7}{'branches':>9}{'open':>6}{'DER':>5}{'loads':>6}  meshed  series  load MW / MVAr")
    for spec in specs:
        r = _row(spec)
        nodes = "" if r["nodes"] is None else r["nodes"]
        print(
            f"{r['spec']:<28}{r['buses']:>6}{nodes:>7}{r['branches']:>9}{r.get('branches_open', ''):>6}{r['ders']:>5}"
            f"{r['loads']:>6}  {'yes' if r['meshed'] else 'no':<6}  {'yes' if r['series'] else 'no':<6}  "
            f"{r['load_mw']:.3f} / {r['load_mvar']:.3f}",
            flush=True,
        )
    if not args.simbench and not args.specs:
        print(f"\nalso: {formats(without='shipped')} (--simbench lists SimBench's suite)")
    return 0
