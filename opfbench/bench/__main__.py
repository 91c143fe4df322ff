"""`python -m opfbench.bench {pf,local,opf,fault,run,learned,frontier,unbalanced} [--json] [options of the benchmark]`."""

from __future__ import annotations

import argparse
import importlib

from opfbench.jsonio import print_json

BENCHES = ("pf", "local", "opf", "fault", "run", "learned", "frontier", "unbalanced")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.bench", description=__doc__)
    parser.add_argument("which", choices=BENCHES)
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    known, _ = parser.parse_known_args(argv)
    module = importlib.import_module(f"opfbench.bench.{known.which}")
    options = hasattr(module, "add_arguments")  # a benchmark with options of its own
    if options:
        module.add_arguments(parser)
    args = parser.parse_args(argv)
    figures = module.run(args) if options else module.run()
    if args.json:
        print_json(figures)
    else:
        module.print_table(figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
