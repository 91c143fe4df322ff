"""`opfbench report`: rebuild the HTML report of a run folder from the files a run, a
forecast run and a fault study wrote, without recomputing anything."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from opfbench.commands.arguments import fraction, path
from opfbench.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="write the HTML report of a run folder (report.html)", description=__doc__)
    p.add_argument("run_dir", type=path, metavar="RUN_DIR", help="folder written by `opfbench run --out RUN_DIR`")
    p.add_argument(
        "--forecast-dir",
        type=path,
        help="folder written by `opfbench forecast --out DIR` "
        "(default reports/forecast when it holds one, else the "
        "committed docs/forecast metrics)",
    )
    p.add_argument(
        "--fault-dir",
        type=path,
        help="folder written by `opfbench fault ... --out DIR` (default reports/fault when it holds one)",
    )
    p.add_argument(
        "--year-dir",
        type=path,
        help="folder written by `opfbench run --period year --out DIR` "
        "(default reports/year when it holds one, else the committed "
        "docs/year summary)",
    )
    p.add_argument("--out", type=file_path, help="report file (default RUN_DIR/report.html)")
    p.add_argument(
        "--price",
        type=fraction,
        help="energy price per kWh for the money rows (default: the run's manifest, else 0.20 EUR/kWh, Eurostat 2023-H2)",
    )
    p.set_defaults(func=run)


def file_path(text: str) -> Path:
    """argparse type: a file's path (`path`), not one that ends with a separator — pathlib
    would drop it and write a file where the user named a folder."""
    if text.endswith((os.sep, "/")):
        raise argparse.ArgumentTypeError(f"{text!r} names a folder; give the report's file name, e.g. {text}report.html")
    return path(text)


def run(args: argparse.Namespace) -> int:
    from opfbench.report import write_report
    from opfbench.report.sources import check_given, holds_run, report_sources

    if not args.run_dir.is_dir():
        raise InputError(f"run folder {args.run_dir} does not exist; write it with `opfbench run --out {args.run_dir}`")
    if not holds_run(args.run_dir):
        raise InputError(f"{args.run_dir} holds no run (no manifest.json); write one with `opfbench run --out {args.run_dir}`")
    for name in ("forecast_dir", "fault_dir", "year_dir"):
        folder = getattr(args, name)
        if folder is not None and not folder.is_dir():
            raise InputError(f"--{name.replace('_', '-')} {folder} does not exist or is not a folder")
    out = check_report_file(args.out if args.out is not None else args.run_dir / "report.html")
    check_given(args.forecast_dir, args.fault_dir, args.year_dir)
    forecast_dir, fault_dir, year_dir = report_sources(args.forecast_dir, args.fault_dir, args.year_dir)
    written = write_report(args.run_dir, forecast_dir, fault_dir, out, args.price, year_dir)
    print(f"wrote {written}", file=sys.stderr)
    return 0


def check_report_file(out: Path) -> Path:
    """The report's file: not a folder; its folder created if missing and writable."""
    if out.is_dir():
        raise InputError(f"--out {out} is a folder; give the report's file name, e.g. {out / 'report.html'}")
    folder = out.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out {out}: cannot create the folder {folder} ({exc.strerror})") from None
    try:  # what the atomic write will do: a temporary file in the folder (os.access trusts root, not /proc)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=f".{out.name}.", suffix=".probe"):
            pass
    except OSError as exc:
        raise InputError(f"--out {out}: cannot write in {folder} ({exc.strerror})") from None
    if out.exists() and not os.access(out, os.W_OK):
        raise InputError(f"--out {out} is not writable")
    return out
