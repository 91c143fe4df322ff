"""Batched power flows remembered by their input, per thread.

A study runs the same batched flow more than once: every closed-loop local rule starts from
the no-action state (the `no-action` strategy's own flow), and the `socp` strategy
evaluates the setpoints whose flow the AC OPF's fast path has just solved. A flow is a
deterministic function of its input — the network, the injections, the options — so the
answer to the same input is the same object: `FlowMemo` keeps the most recent answers of
cold-started batched flows (no `v0`), looked up by a cheap fingerprint (network, options,
shape, the sum of the injections) and confirmed byte for byte, so no two different
inputs can share an answer. The answers' arrays are made read-only: one caller cannot
change another's. At most MEMO_BYTES of inputs and answers are kept per thread (least
recently used dropped first); a batch larger than a quarter of that is not kept.
Benchmarks that time a flow on the same input again call `forget_flows` first.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Callable, Hashable, TypeVar

import numpy as np

from opfbench.network import Network
from opfbench.powerflow.common import PowerFlowResult
from opfbench.state import PROCESS

T = TypeVar("T")
MEMO_BYTES = 64 * 2**20  # per thread: inputs and answers kept (estimated from their arrays)

_local = threading.local()


def _frozen(result: PowerFlowResult) -> PowerFlowResult:
    for arr in (result.v, result.converged, result.iterations):
        arr.flags.writeable = False
    return result


class FlowMemo:
    """The recent answers of one thread (module docstring)."""

    def __init__(self, limit_bytes: int = MEMO_BYTES):
        self.limit, self.used = limit_bytes, 0
        self._entries: OrderedDict[tuple, tuple[np.ndarray, PowerFlowResult, int]] = OrderedDict()

    @staticmethod
    def _key(net: Network, options: Hashable, s: np.ndarray) -> tuple:
        return (net, options, s.shape, complex(s.sum()))  # Network hashes by identity

    def get(self, net: Network, options: Hashable, s: np.ndarray) -> PowerFlowResult | None:
        """The answer to exactly these injections `s` (complex, C-contiguous), or None."""
        key = self._key(net, options, s)
        entry = self._entries.get(key)
        if entry is None or entry[0].tobytes() != s.tobytes():
            return None
        self._entries.move_to_end(key)
        return entry[1]

    def put(self, net: Network, options: Hashable, s: np.ndarray, result: PowerFlowResult) -> PowerFlowResult:
        """Keep `result` as the answer to `s` (its arrays made read-only) and return it."""
        size = 2 * s.nbytes + result.converged.nbytes + result.iterations.nbytes  # v is as large as s
        if size > self.limit // 4:
            return result
        key = self._key(net, options, s)
        old = self._entries.pop(key, None)
        if old is not None:
            self.used -= old[2]
        self._entries[key] = (s.copy(), _frozen(result), size)
        self.used += size
        while self.used > self.limit:
            self.used -= self._entries.popitem(last=False)[1][2]
        return result


def flow_memo() -> FlowMemo:
    """This thread's memo."""
    found: FlowMemo | None = getattr(_local, "memo", None)
    if found is None:
        found = _local.memo = FlowMemo()
    return found


def forget_flows() -> None:
    """Empty this thread's memo (benchmarks timing the flows themselves)."""
    _local.memo = FlowMemo()


PROCESS.on_reset("power-flow answers (the calling thread's)", forget_flows)


def cold(fn: Callable[..., T], *args, **kwargs) -> T:
    """`fn(*args, **kwargs)` with this thread's memo emptied first (a benchmark's timed call)."""
    forget_flows()
    return fn(*args, **kwargs)
