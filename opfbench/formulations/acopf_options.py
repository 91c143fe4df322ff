"""The formulations' option vocabularies, written once and light to import (the CLI and
the study config offer them as choices before anything heavy is loaded).

- AC OPF solver path (`run_acopf(solver=...)`): "auto" — the certified fast path through
  the SOCP relaxation, IPOPT for the snapshots it does not certify; "ipopt" — IPOPT on
  every snapshot (the paper's question: how often a nonlinear solver fails).
- AC OPF failure policy (`run_acopf(fallback=...)`): "chain" — warm IPOPT → cold IPOPT →
  the SOCP's setpoints → no action, each only if AC-feasible; "paper" — IPOPT once, on
  failure no action, as the paper did.
"""

from __future__ import annotations

from typing import Literal

from opfbench.errors import InputError

AcopfSolver = Literal["auto", "ipopt"]
ACOPF_SOLVERS: tuple[AcopfSolver, ...] = ("auto", "ipopt")
Fallback = Literal["chain", "paper"]
FALLBACKS: tuple[Fallback, ...] = ("chain", "paper")


def check_option(name: str, value: object, allowed: tuple) -> None:
    """InputError naming the option unless `value` is one of `allowed`."""
    if value not in allowed:
        raise InputError(f"unknown {name} {value!r}; choose {', '.join(map(str, allowed))}")
