"""`opfbench strategies [--plugin MODULE] [--json]`: every registered strategy — its kind,
what it reads, whether it reads a forecast or gives a lower bound, the networks it
supports and its options (type, default, allowed values) — built-in and plugins."""

from __future__ import annotations

import argparse

from opfbench.commands.arguments import add_plugin_option, load_plugins, print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("strategies", help="list every strategy (built-in and plugins) with its options")
    add_plugin_option(p)
    p.add_argument("--json", action="store_true", help="print one JSON list, one object per strategy")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from opfbench.registry.catalog import specs

    load_plugins(args)
    entries = [s.describe() for s in specs()]
    if args.json:
        print_json(entries)
        return 0
    for e in entries:
        flags = [e["kind"], "closed loop" if e["closed_loop"] else "", "reads a forecast" if e["uses_forecast"] else ""]
        flags += ["lower bound" if e["lower_bound"] else "", f"{'/'.join(e['supports'])} networks"]
        source = "" if e["source"] == "opfbench" else f"  [plugin {e['source']}]"
        print(f"{e['name']}{source}: {e['summary']}")
        print(f"    {', '.join(f for f in flags if f)}; reads {', '.join(e['reads']) or 'nothing'}")
        for o in e["options"]:
            allowed = f" ∈ {{{', '.join(o['allowed'])}}}" if "allowed" in o else ""
            origin = f" (run default: --{o['default_from'].replace('_', '-')})" if "default_from" in o else ""
            print(f"    {o['name']}={o['default']}  {o['type']}{allowed}{origin}: {o['help']}")
        if e["fixed"]:
            print(f"    fixed: {', '.join(f'{k}={v}' for k, v in e['fixed'].items())}")
    print("\nLabels: NAME or NAME:key=value,… (e.g. volt-var:curve=a), in run, snapshot and fault --strategies.")
    return 0
