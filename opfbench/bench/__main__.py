"""`python -m opfbench.bench {pf,local,opf} [--json]`."""

from __future__ import annotations

import argparse
import importlib
import json

BENCHES = ("pf", "local", "opf", "fault")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.bench", description=__doc__)
    parser.add_argument("which", choices=BENCHES)
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--large", action="store_true", help="pf only: add the large-feeder figures (feeder10k)")
    args = parser.parse_args(argv)
    if args.large and args.which != "pf":
        parser.error("--large applies to the pf benchmark only")
    module = importlib.import_module(f"opfbench.bench.{args.which}")
    figures = module.run(large=True) if args.large else module.run()
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        module.print_table(figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
