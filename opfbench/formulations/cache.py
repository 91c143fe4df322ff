"""Caches of the formulations, none of which hands one mutable object to two callers at once.

- `per_thread(net, key, build)`: a solver object (an IPOPT or Clarabel instance, which
  keeps per-solve state) built once per (network, key) *per thread*, so concurrent
  tasks never share one; sequential callers in one thread reuse it (building is the
  expensive part: CasADi derivatives, cvxpy canonicalization). The PER_THREAD most
  recently used objects are kept (they hold their network).
- `per_scenario(scenario, key, compute)`: results computed once per (Scenario object,
  key) — the SOCP solves that `acopf` (its bound, fast path and fallback) and `socp`
  both need for the same scenario and k. Keyed weakly: an entry goes with its scenario
  (results are immutable records that do not refer to it).
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from typing import Callable, Hashable, TypeVar

from opfbench.network import Network
from opfbench.scenario import Scenario

T = TypeVar("T")
PER_THREAD = 16  # solver objects kept per thread (least recently used dropped first)

_local = threading.local()
_scenario_lock = threading.Lock()
_per_scenario: "weakref.WeakKeyDictionary[Scenario, dict]" = weakref.WeakKeyDictionary()


def per_thread(net: Network, key: Hashable, build: Callable[[], T]) -> T:
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


def per_scenario(scenario: Scenario, key: Hashable, compute: Callable[[], T]) -> T:
    """`compute()` once per (scenario object, key); later calls, from any thread, return it."""
    with _scenario_lock:
        entries = _per_scenario.setdefault(scenario, {})
        if key in entries:
            return entries[key]
    value = compute()
    with _scenario_lock:
        return _per_scenario.setdefault(scenario, {}).setdefault(key, value)
