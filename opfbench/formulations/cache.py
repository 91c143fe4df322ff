"""Caches of the formulations, none of which hands one mutable object to two callers at once.

- `per_thread(net, key, build)`: a solver object (an IPOPT or Clarabel instance, which
  keeps per-solve state) built once per (network, key) *per thread*, so concurrent
  tasks never share one; sequential callers in one thread reuse it (building is the
  expensive part: CasADi derivatives, cvxpy canonicalization).
- `per_scenario(scenario, key, compute)`: results computed once per (Scenario object,
  key) — the SOCP solves that `acopf` (its bound, fast path and fallback) and `socp`
  both need for the same scenario and k. Results are immutable records.

Both are keyed weakly: an entry goes with its network or scenario.
"""

from __future__ import annotations

import threading
import weakref
from typing import Callable, Hashable, TypeVar

from opfbench.network import Network
from opfbench.scenario import Scenario

T = TypeVar("T")

_local = threading.local()
_scenario_lock = threading.Lock()
_per_scenario: "weakref.WeakKeyDictionary[Scenario, dict]" = weakref.WeakKeyDictionary()


def per_thread(net: Network, key: Hashable, build: Callable[[], T]) -> T:
    """`build()` once per (net, key) in the calling thread; later calls return that object."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = weakref.WeakKeyDictionary()
    per_net = cache.setdefault(net, {})
    if key not in per_net:
        per_net[key] = build()
    return per_net[key]


def per_scenario(scenario: Scenario, key: Hashable, compute: Callable[[], T]) -> T:
    """`compute()` once per (scenario object, key); later calls, from any thread, return it."""
    with _scenario_lock:
        entries = _per_scenario.setdefault(scenario, {})
        if key in entries:
            return entries[key]
    value = compute()
    with _scenario_lock:
        return _per_scenario.setdefault(scenario, {}).setdefault(key, value)
