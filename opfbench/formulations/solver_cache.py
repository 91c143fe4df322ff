"""The formulations' two caches, neither of which hands one mutable object to two callers
at once, and neither of which depends on which Scenario object a caller holds.

- `per_thread(net, key, build)`: a solver object (an IPOPT or Clarabel instance, which
  keeps per-solve state) built once per (network, key) *per thread*, so concurrent
  tasks never share one; sequential callers in one thread reuse it (building is the
  expensive part: CasADi derivatives, cvxpy canonicalization). The PER_THREAD most
  recently used objects are kept (they hold their network).
- `SolveCache`: solves keyed on the data they solved — the network (an immutable object,
  by identity), the options, and the snapshot's data vector θ — shared by every caller in
  the process and thread-safe; the values are immutable records. Keys hold θ's bytes
  themselves up to EXACT_KEY_BYTES (exact: equal keys are equal data) and a 128-bit BLAKE2
  digest of them above (large feeders, where θ is long). The least recently used entries
  beyond the byte limit (keys and values, estimated) are dropped.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from typing import Callable, Generic, Hashable, Sequence, TypeVar

import numpy as np

from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network
from opfbench.state import PROCESS

T = TypeVar("T")
PER_THREAD = 16  # solver objects kept per thread (least recently used dropped first)
EXACT_KEY_BYTES = 4096  # θ up to this size is its own key (512 float64: feeders up to ~250 buses)

_local = threading.local()


def per_thread(net: Network | PhaseNetwork, key: Hashable, build: Callable[[], T]) -> T:
    """`build()` once per (net, key) in the calling thread; later calls return that object."""
    cache: OrderedDict | None = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = OrderedDict()
    entry = (net, key)  # Network hashes by identity
    if entry in cache:
        cache.move_to_end(entry)
        return cache[entry]
    cache[entry] = value = build()
    if len(cache) > PER_THREAD:
        cache.popitem(last=False)
    return value


def forget_solvers() -> None:
    """Drop the calling thread's solver objects."""
    _local.cache = OrderedDict()


PROCESS.on_reset("formulation solver objects (the calling thread's)", forget_solvers)

Key = tuple[Network, Hashable, bytes]


class SolveCache(Generic[T]):
    """Solves by their data (see the module docstring), at most `limit_bytes` as counted by
    `KEY_BYTES` + len(θ key) + `size(value)` per entry."""

    KEY_BYTES = 200  # an entry's key tuple and dict slot, without θ's bytes (estimate)

    def __init__(self, limit_bytes: int, size: Callable[[T], int]):
        self.limit, self.used = limit_bytes, 0
        self._size = size
        self._entries: OrderedDict[Key, T] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def keys(net: Network, options: Hashable, thetas: np.ndarray) -> list[Key]:
        """One key per row of `thetas` (S, n_θ) float64."""
        thetas = np.ascontiguousarray(thetas, dtype=np.float64)
        if thetas.shape[-1] * 8 <= EXACT_KEY_BYTES:
            return [(net, options, row.tobytes()) for row in thetas]
        return [(net, options, hashlib.blake2b(row, digest_size=16).digest()) for row in thetas]

    def _entry_bytes(self, key: Key, value: T) -> int:
        return self.KEY_BYTES + len(key[2]) + self._size(value)

    def get_many(self, keys: Sequence[Key]) -> list[T | None]:
        """The cached value of each key (None where absent); hits become the most recent."""
        with self._lock:
            out = [self._entries.get(key) for key in keys]
            for key, value in zip(keys, out, strict=True):
                if value is not None:
                    self._entries.move_to_end(key)
            return out

    def put_many(self, items: Sequence[tuple[Key, T]]) -> None:
        """Store values (a key already present keeps its value), then drop the least
        recently used entries beyond the limit (never the last one)."""
        with self._lock:
            for key, value in items:
                if key not in self._entries:
                    self._entries[key] = value
                    self.used += self._entry_bytes(key, value)
            while self.used > self.limit and len(self._entries) > 1:
                key, value = self._entries.popitem(last=False)
                self.used -= self._entry_bytes(key, value)

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self.used = 0
