"""`opfbench cases [SPEC …]`: the shipped cases (or the given specs: files, simbench:CODE)
with bus/branch/DER/load counts; `--simbench` lists the SimBench codes the field suite
runs."""

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


def run(args: argparse.Namespace) -> int:
    from opfbench.cases import CASE_NAMES
    from opfbench.io import load_case
    from opfbench.io.simbench import SUITE

    specs = list(args.specs) or list(CASE_NAMES)
    if args.simbench:
        specs += [f"simbench:{code}" for code in SUITE]
    cases = [load_case(spec) for spec in specs]
    rows = [c.network.summary() | {"spec": c.spec, "series": c.series is not None, "notes": list(c.notes)} for c in cases]
    if args.json:
        print_json(rows)
        return 0
    print(f"{'case':<28}{'buses':>6}{'branches':>9}{'open':>6}{'DER':>5}{'loads':>6}  meshed  series  load MW / MVAr")
    for r in rows:
        print(
            f"{r['spec']:<28}{r['buses']:>6}{r['branches']:>9}{r['branches_open']:>6}{r['ders']:>5}{r['loads']:>6}  "
            f"{'yes' if r['meshed'] else 'no':<6}  {'yes' if r['series'] else 'no':<6}  {r['load_mw']:.3f} / {r['load_mvar']:.3f}"
        )
    if not args.simbench and not args.specs:
        print(f"\nalso: {formats(without='shipped')} (--simbench lists SimBench's suite)")
    return 0
