"""Argument helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

from opfbench.jsonio import print_json

__all__ = ["add_operating_point", "fraction", "number", "path", "print_json", "share"]

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
