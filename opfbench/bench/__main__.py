"""`python -m opfbench.bench {pf,local,opf,fault,run,learned,frontier} [--json] [options of the benchmark]`;
`python -m opfbench.bench all [--json] [--markdown] …` (every benchmark, one record, `record`)
and `python -m opfbench.bench check NEW` (the regression guard, `check`)."""

from __future__ import annotations

import argparse
import importlib
import sys

from opfbench.errors import InputError
from opfbench.jsonio import print_json

BENCHES = ("pf", "local", "opf", "fault", "run", "learned", "frontier")
COMMANDS = {"all": "record", "check": "check"}  # the record of every benchmark, and the guard


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.bench", description=__doc__)
    parser.add_argument("which", choices=BENCHES + tuple(COMMANDS))
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    known, _ = parser.parse_known_args(argv)
    module = importlib.import_module(f"opfbench.bench.{COMMANDS.get(known.which, known.which)}")
    options = hasattr(module, "add_arguments")  # a benchmark with options of its own
    if options:
        module.add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        figures = module.run(args) if options else module.run()
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print_json(figures)
    else:
        module.print_table(figures)
    return module.exit_code(figures) if hasattr(module, "exit_code") else 0


if __name__ == "__main__":
    raise SystemExit(main())
