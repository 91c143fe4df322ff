"""The one timing helper: wall-clock intervals in milliseconds (`time.perf_counter`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def now() -> float:
    """A start mark for `elapsed_ms` (seconds, arbitrary origin)."""
    return time.perf_counter()


def elapsed_ms(start: float) -> float:
    """Milliseconds since `start` (a value of `now()`)."""
    return (time.perf_counter() - start) * 1e3


def best_ms(fn: Callable[[], T], repeats: int, cpu: bool = False) -> tuple[float, T]:
    """Best (minimum) wall time in ms of `repeats` calls of `fn`, and the last call's result;
    with `cpu`, the process's CPU time instead (`time.process_time`): for a single-threaded
    call the time it ran, not the time it waited for a core on a machine other jobs share
    (on a quiet machine the two are the same)."""
    clock = time.process_time if cpu else time.perf_counter
    best, result = float("inf"), None
    for _ in range(max(1, repeats)):
        start = clock()
        result = fn()
        best = min(best, (clock() - start) * 1e3)
    return best, result  # type: ignore[return-value]
