"""`opfbench` command line. Each subcommand lives in `opfbench/commands/<name>.py` and
provides `register(subparsers)` (adds its parser and sets `func`) — this file only
wires them together and turns opfbench errors into a stderr message and exit code 2.

Command modules keep their top-level imports light (numpy, pandas, the network model);
torch, statsmodels and matplotlib are imported inside a command only when a forecasting
model or a plot needs them, so `opfbench --help`, `pf`, `snapshot` and `run` start fast."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Any

from opfbench.errors import OpfbenchError

COMMANDS = ("cases", "pf", "snapshot", "strategies", "table", "data", "run", "forecast", "report", "fault")


class _Once(argparse.Action):
    """argparse's plain store, except that a second occurrence of the option is refused
    (argparse would keep the last value silently: `--der 7:PV:0.3 --der 8:PV:0.3`)."""

    def __call__(
        self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option_string: str | None = None
    ) -> None:
        given = getattr(parser, "given", None)
        if given is not None and self.dest in given:
            parser.error(f"{'/'.join(self.option_strings) or self.dest} given twice; give it once")
        if given is not None:
            given.add(self.dest)
        setattr(namespace, self.dest, values)


class CommandParser(argparse.ArgumentParser):
    """The command line's parser (its subcommands' too): an option that stores one value
    (or one list, e.g. --strategies) is given at most once; repeatable options say so
    (action="append", --plugin)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.given: set[str] | None = None
        self.register("action", None, _Once)
        self.register("action", "store", _Once)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self.given = set()
        return super().parse_known_args(args, namespace)


def build_parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog="opfbench", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMANDS:
        importlib.import_module(f"opfbench.commands.{name}").register(sub)
    return parser


PIPE_CLOSED = 141
"""Exit code when the reader of stdout went away (`opfbench cases | head -1`): 128 + SIGPIPE,
what a shell reports for any program its pipe's reader left."""


def main(argv: list[str] | None = None) -> int:
    """Run the command line; Ctrl-C anywhere stops with exit code 130 and one line (what a
    study kept, `opfbench.errors.Stopped`); a closed stdout stops quietly."""
    try:
        return _main(argv)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes it
        return PIPE_CLOSED


def _main(argv: list[str] | None) -> int:
    command = "opfbench"
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # argparse already printed its message
            return 0 if exc.code == 0 else 2
        command = f"opfbench {args.command}"
        return _run(args)
    except KeyboardInterrupt as exc:
        print(f"\n{command}: stopped" + (f"; {exc}" if str(exc) else " (Ctrl-C)"), file=sys.stderr, flush=True)
        return 130


def _run(args: argparse.Namespace) -> int:
    try:
        return int(args.func(args) or 0)
    except OpfbenchError as exc:
        print(f"opfbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:
        case = f" on case {args.case!r}" if getattr(args, "case", None) else ""
        print(
            f"opfbench {args.command}: error: out of memory{case}: the problem is too large for this "
            "machine's memory (a smaller case, or fewer snapshots)",
            file=sys.stderr,
        )
        return 2
