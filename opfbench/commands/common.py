"""Argument helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import math

from opfbench.jsonio import print_json

__all__ = ["add_operating_point", "fraction", "number", "print_json", "share"]


def number(text: str) -> float:
    """argparse type: a finite number (range checks that need the input's name come before
    the work, in the command)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
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


def add_operating_point(parser: argparse.ArgumentParser) -> None:
    """--load-scale and --der-scale, as every snapshot-type command takes them."""
    parser.add_argument("--load-scale", type=fraction, default=1.0, help="multiplier on every nominal load (default 1.0)")
    parser.add_argument(
        "--der-scale", type=share, default=0.8, help="DER active power as a fraction of rating, 0..1 (default 0.8)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
