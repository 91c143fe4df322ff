"""One BLAS thread for the small, many products of the power flows and the OPF models:
threads waiting on a shared machine cost more than such products gain from them."""

from __future__ import annotations

import functools
from collections.abc import Iterator
from contextlib import contextmanager

from threadpoolctl import ThreadpoolController


@functools.cache
def _blas() -> ThreadpoolController:
    """The BLAS libraries' controller, found once (finding them costs milliseconds)."""
    return ThreadpoolController().select(user_api="blas")


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS on one thread inside. Sets and restores only the libraries not already on one
    thread (threadpoolctl's `limit` queries every library on each call: ~0.1 ms, hundreds
    of times in a closed loop)."""
    changed = [(lib, lib.num_threads) for lib in _blas().lib_controllers if lib.num_threads != 1]
    for lib, _ in changed:
        lib.set_num_threads(1)
    try:
        yield
    finally:
        for lib, threads in changed:
            lib.set_num_threads(threads)
