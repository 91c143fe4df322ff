"""Argument helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

from opfbench.exact import number_text
from opfbench.io.sources import formats
from opfbench.jsonio import print_json

__all__ = [
    "CASE_HELP",
    "STRATEGY_HELP",
    "add_case_options",
    "add_execution_options",
    "add_operating_point",
    "add_plugin_option",
    "case_spec",
    "fraction",
    "load_plugins",
    "number",
    "path",
    "print_json",
    "share",
    "strategy_labels",
    "workers",
]

CASE_HELP = f"{formats()}; options ?der=…&der-pf=… as --der/--der-pf"

STRATEGY_HELP = (
    "strategy configurations NAME or NAME:key=value,… (e.g. lfma volt-var volt-var:curve=a cosphi-p:pf_min=0.95); "
    "`opfbench strategies` lists every strategy and its options"
)

DECIMAL = re.compile(r"^\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*$", re.ASCII)
"""A decimal number as written on a command line (Python's float() also reads 1_0 and ١)."""


def number(text: str) -> float:
    """argparse type: a finite decimal number (range checks that need the input's name come
    before the work, in the command)."""
    if not DECIMAL.match(text):
        if text.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise argparse.ArgumentTypeError(f"must be finite, got {text}")
        raise argparse.ArgumentTypeError(f"not a number: {text!r}")
    value = float(text)
    if not math.isfinite(value):  # 1e999
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def fraction(text: str) -> float:
    """argparse type: a finite number ≥ 0 (a share of rating, a multiplier, a reserve k)."""
    value = number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number ≥ 0, got {text}")
    return value


def share(text: str) -> float:
    """argparse type: a share of a whole, a finite number in [0, 1] (DER output of rating)."""
    value = fraction(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must lie in [0, 1], got {text}")
    return value


def path(text: str) -> Path:
    """argparse type: a file or folder path — not empty (that would silently mean the
    current folder) and without NUL bytes."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; give a file or folder name (. for the current folder)")
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"{text!r} contains a NUL byte")
    return Path(text)


def add_operating_point(parser: argparse.ArgumentParser) -> None:
    """--load-scale and --der-scale, as every snapshot-type command takes them."""
    parser.add_argument("--load-scale", type=fraction, default=1.0, help="multiplier on every nominal load (default 1.0)")
    parser.add_argument(
        "--der-scale", type=share, default=0.8, help="DER active power as a fraction of rating, 0..1 (default 0.8)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def add_case_options(parser: argparse.ArgumentParser) -> None:
    """--der and --der-pf: DER on a user's own case, and the generic inverters' rating."""
    parser.add_argument(
        "--der",
        default=None,
        help="DER on a case without any: 'gens' (a MATPOWER file's non-slack generators) or BUS:KIND:MW[:ENERGY],… "
        "(KIND PV, DFIG or inverter; e.g. 10:PV:0.6,27:DFIG:0.6); the same as the case option ?der=",
    )
    parser.add_argument(
        "--der-pf",
        type=number,
        default=None,
        help="generic inverters' rating S̄ = P̄/PF where the source gives no larger one (default 0.90: "
        "VDE-AR-N 4105's cos φ 0.90 at full output); the same as ?der-pf=",
    )


def case_spec(case: str, args: argparse.Namespace) -> str:
    """`case` with the --der/--der-pf options added to its spec (`opfbench.io.spec`)."""
    opts = [f"der={args.der}"] if getattr(args, "der", None) is not None else []
    opts += [f"der-pf={number_text(args.der_pf)}"] if getattr(args, "der_pf", None) is not None else []
    if not opts:
        return case
    return case + ("&" if "?" in case else "?") + "&".join(opts)


def workers(text: str) -> int:
    """argparse type: local worker processes, a whole number from 1 to this machine's
    cores (more only slow each other down; a Dask cluster via --scheduler has more)."""
    from opfbench.study.execution import cores

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {n}")
    if n > cores():
        raise argparse.ArgumentTypeError(
            f"{n} worker processes on {cores()} cores; give at most {cores()} (or --scheduler for a Dask cluster)"
        )
    return n


def add_execution_options(parser: argparse.ArgumentParser, default_workers: int | None = None) -> None:
    """How a study runs (`opfbench.study.engine`): --workers (default `default_workers`,
    None: every core) or --scheduler (not both), --fresh, --quiet."""
    where = parser.add_mutually_exclusive_group()
    default = "every core" if default_workers is None else str(default_workers)
    where.add_argument(
        "--workers",
        type=workers,
        default=default_workers,
        help=f"local worker processes (default: {default}; never more than tasks to run; 1 runs in this process)",
    )
    where.add_argument("--scheduler", default=None, help="run on an existing Dask cluster, e.g. tcp://HOST:8786")
    parser.add_argument("--fresh", action="store_true", help="discard a previous run of another configuration in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress output")


def add_plugin_option(parser: argparse.ArgumentParser) -> None:
    """--plugin FILE.py|MODULE, repeatable: strategies of your own (`opfbench.plugins`)."""
    parser.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="MODULE",
        help="load the local rules of a plugin: a .py file or an importable module (repeatable); see docs/custom_rule.py",
    )


def load_plugins(args: argparse.Namespace) -> None:
    """Load the --plugin modules (InputError naming a bad one), before any work."""
    from opfbench.plugins import load

    for ref in getattr(args, "plugin", None) or []:
        load(ref)


def strategy_labels(labels: list[str], args: argparse.Namespace) -> list[str]:
    """The --plugin modules loaded, then every label of `labels` checked and canonical
    (`registry.configuration`; InputError naming a bad one), before any work."""
    from opfbench.registry.catalog import canonical

    load_plugins(args)
    return [canonical(label) for label in labels]
