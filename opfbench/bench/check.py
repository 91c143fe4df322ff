"""`python -m opfbench.bench check NEW [--baseline FILE] [--tolerance 0.25]`: the regression
guard. Compares a new benchmark record (`python -m opfbench.bench all --out NEW`) with the
committed one (`docs/benchmarks.json`) key by key, each key as a ratio to its peer in the
same run (`record.Bench.guards`: e.g. the batched power flow over power-grid-model's, a
time over the reference workload's), so a slower or busier machine moves both and the
ratio stays. A guarded key whose ratio grew by more than the tolerance (25 %) is flagged
"worse", as is one the new record lacks ("missing"); a key the baseline lacks is "new".
Exit status 1 when any key is flagged, else 0; 2 for a file that is not a record.

Not part of the test suite (it would time things there): run it after `all` when the
machine is quiet (README, docs/BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
from pathlib import Path

from opfbench.bench.record import RECORD, read_record
from opfbench.errors import InputError

TOLERANCE = 0.25  # a key more than 25 % worse than the baseline, relative to its peer, is flagged
OK, WORSE, MISSING, NEW = "ok", "worse", "missing", "new"


@dataclass(frozen=True)
class Verdict:
    """One guarded key: its peer, key/peer in the baseline and in the new record, the
    relative change of that ratio (positive = slower), and the status."""

    key: str
    peer: str
    baseline: float | None
    new: float | None
    change: float | None
    status: str


def _ratio(record: dict, key: str, peer: str) -> float | None:
    value, base = record["keys"].get(key), record["keys"].get(peer)
    if value is None or base is None or base <= 0 or value < 0:
        return None
    return value / base


def compare(new: dict, baseline: dict, tolerance: float = TOLERANCE) -> list[Verdict]:
    """A verdict per key the new record guards (its `guards`, then any the baseline
    guards that the new one lost)."""
    guards = dict(new["guards"]) | {k: p for k, p in baseline["guards"].items() if k not in new["guards"]}
    out = []
    for key, peer in guards.items():
        was, now_ = _ratio(baseline, key, peer), _ratio(new, key, peer)
        if now_ is None:
            status, change = MISSING, None
        elif was is None:
            status, change = NEW, None
        else:
            change = now_ / was - 1.0
            status = WORSE if change > tolerance else OK
        out.append(Verdict(key, peer, was, now_, change, status))
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("new", type=Path, help="the new record (`python -m opfbench.bench all --out FILE`)")
    parser.add_argument("--baseline", type=Path, default=RECORD, help=f"the record to compare with (default {RECORD})")
    parser.add_argument(
        "--tolerance", type=float, default=TOLERANCE, help="flag a ratio that grew by more than this (0.25 = 25 %%)"
    )


def run(args: argparse.Namespace) -> dict:
    if not 0 < args.tolerance < 10:
        raise InputError(f"--tolerance must be a fraction in (0, 10), got {args.tolerance}")
    new, baseline = read_record(args.new), read_record(args.baseline)
    verdicts = compare(new, baseline, args.tolerance)
    return {
        "new": str(args.new),
        "new_commit": new.get("commit"),
        "baseline": str(args.baseline),
        "baseline_commit": baseline.get("commit"),
        "tolerance": args.tolerance,
        "flagged": [v.key for v in verdicts if v.status in (WORSE, MISSING)],
        "verdicts": [asdict(v) for v in verdicts],
    }


def exit_code(figures: dict) -> int:
    return 1 if figures["flagged"] else 0


def print_table(f: dict) -> None:
    print(
        f"{f['new']} ({f['new_commit'] or 'unknown commit'}) against {f['baseline']} ({f['baseline_commit'] or 'unknown commit'})"
    )
    print(f"  {'key':34s} {'peer':32s} {'baseline':>10s} {'new':>10s} {'change':>8s}")
    for v in f["verdicts"]:

        def num(x: float | None) -> str:
            return "—" if x is None else f"{x:.4g}"

        change = "—" if v["change"] is None else f"{100 * v['change']:+.0f} %"
        print(f"  {v['key']:34s} {v['peer']:32s} {num(v['baseline']):>10s} {num(v['new']):>10s} {change:>8s}  {v['status']}")
    flagged = f["flagged"]
    print(
        f"{len(flagged)} key(s) more than {100 * f['tolerance']:.0f} % worse or missing"
        + (f": {', '.join(flagged)}" if flagged else "")
    )
