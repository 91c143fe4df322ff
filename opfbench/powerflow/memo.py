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

Each snapshot's answer is a function of its own injections and warm start alone, whatever
else is in the batch (`fixed_point`), so the answers are also remembered per snapshot
(`RowMemo`): a closed-loop rule whose iteration retraces another's (Volt-VAR with a
Volt-Watt that never acts, a reserve k whose limit never binds, a night hour that no night
mode changes) or an AC evaluation of setpoints another strategy evaluated gets those
snapshots' voltages, verdict and iteration count without solving them again, and only the
others are solved. A snapshot is looked up by a 128-bit digest of its exact bytes
(injections, and warm start or its absence; `row_digests`) under its network and options,
and confirmed against the remembered snapshot's bytes, so no two different snapshots can
share an answer; ROW_MEMO_BYTES of snapshots and answers are kept per thread (oldest batches
dropped first).
Benchmarks that time a flow on the same input again call `forget_flows` first.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Callable, Hashable, TypeVar

import numpy as np
from numba import njit

from opfbench.network import Network
from opfbench.powerflow.common import PowerFlowResult
from opfbench.state import PROCESS

T = TypeVar("T")
MEMO_BYTES = 64 * 2**20  # per thread: inputs and answers kept (estimated from their arrays)
ROW_MEMO_BYTES = 768 * 2**20  # per thread: the per-snapshot inputs and answers kept (`RowMemo`; the inputs take 1–2× the answers)
_ROW_OVERHEAD = 160  # bytes per remembered snapshot beyond its voltages (its digest and table entry)

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


_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_SEEDS = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xD6E8FEB86659FD93))


@njit(cache=True, inline="always")
def _mix(z):
    """splitmix64's finalizer: a bijection of 64-bit words in which every input bit moves
    every output bit."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _lanes(words: np.ndarray, a, b, offset: int):
    """Two sums of `_mix` over `words`, each word keyed by its position (from `offset`) with
    its own key per sum: each word's term is independent of the others' (no chain to wait
    on), and a change of any one word changes both sums (`_mix` is a bijection)."""
    for j in range(words.size):
        position = np.uint64(offset + j + 1)
        a += _mix(words[j] ^ (position * _SEEDS[0]))
        b += _mix(words[j] + (position * _SEEDS[1]))
    return a, b


@njit(cache=True)
def _digests(s_words: np.ndarray, v_words: np.ndarray, tag: np.uint64, out: np.ndarray) -> None:
    """out[i] ← the two sums (`_lanes`) over row i of `s_words` then of `v_words` (S, w)
    uint64, started from `tag`, each mixed once more."""
    for i in range(s_words.shape[0]):
        a, b = _lanes(s_words[i], tag, tag, 0)
        a, b = _lanes(v_words[i], a, b, s_words.shape[1])
        out[i, 0], out[i, 1] = _mix(a), _mix(b ^ _SEEDS[0])


def row_digests(s: np.ndarray, v0: np.ndarray | None) -> list[bytes]:
    """A 16-byte digest of each snapshot's exact bytes: its injections `s` (S, n) complex
    and warm start `v0` (S, n) complex, or the absence of one (`RowMemo`); both
    C-contiguous."""
    s_words, v_words = snapshot_words(s, v0)
    out = np.empty((s.shape[0], 2), dtype=np.uint64)
    _digests(s_words, v_words, np.uint64(0 if v0 is None else 1), out)
    return out.view("V16").ravel().tolist()


def snapshot_words(s: np.ndarray, v0: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Each snapshot's exact bytes as 64-bit words: its injections (S, 2n) and its warm
    start (S, 2n), or (S, 0) for its absence; views of C-contiguous complex `s` and `v0`."""
    return s.view(np.uint64), np.zeros((s.shape[0], 0), dtype=np.uint64) if v0 is None else v0.view(np.uint64)


@njit(cache=True)
def _same_rows(a_s, a_v, a_rows, b_s, b_v, b_rows, out) -> None:
    """out[i] ← whether row a_rows[i] of (a_s, a_v) and row b_rows[i] of (b_s, b_v) hold the
    same words (equally wide), read in place up to the first difference."""
    for i in range(a_rows.size):
        x, y = a_rows[i], b_rows[i]
        same = True
        for j in range(a_s.shape[1]):
            if a_s[x, j] != b_s[y, j]:
                same = False
                break
        if same:
            for j in range(a_v.shape[1]):
                if a_v[x, j] != b_v[y, j]:
                    same = False
                    break
        out[i] = same


def same_snapshots(
    a: tuple[np.ndarray, np.ndarray], a_rows: np.ndarray, b: tuple[np.ndarray, np.ndarray], b_rows: np.ndarray
) -> np.ndarray:
    """Per pair, whether snapshot `a_rows[i]` of the words `a` and snapshot `b_rows[i]` of
    the words `b` (`snapshot_words`) are the same bytes: injections, and warm start or its
    absence."""
    out = np.zeros(len(a_rows), dtype=bool)
    if a[0].shape[1] == b[0].shape[1] and a[1].shape[1] == b[1].shape[1]:
        _same_rows(a[0], a[1], np.asarray(a_rows, dtype=np.int64), b[0], b[1], np.asarray(b_rows, dtype=np.int64), out)
    return out


# a remembered batch: (network, options), digests, inputs (`snapshot_words`), answers, bytes
_Batch = tuple[tuple, list[bytes], tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], int]


class RowMemo:
    """The per-snapshot answers of one thread (module docstring): `find` the remembered
    answers of some snapshots, `put` those of freshly solved ones; batches of answers are
    dropped oldest first beyond `limit_bytes`. A snapshot found by its digest is served only
    if its bytes are those of the remembered snapshot (kept with its answer), so no two
    different snapshots can share an answer, however their digests fall."""

    def __init__(self, limit_bytes: int = ROW_MEMO_BYTES):
        self.limit, self.used = limit_bytes, 0
        self._tables: dict[tuple, dict[bytes, tuple[int, int]]] = {}  # (network, options) → digest → (batch, row)
        self._batches: OrderedDict[int, _Batch] = OrderedDict()
        self._next = 0

    def find(
        self, net: Network, options: Hashable, keys: list[bytes], s: np.ndarray, v0: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Which snapshots (digests `keys` of injections `s` (S, n) and warm start `v0`, as
        `row_digests`) have a remembered answer: a mask (S,), and arrays of voltages (S, n),
        converged (S,) and iterations (S,) holding those answers in their rows — the other
        rows are for the caller to fill. Each batch's hits are confirmed in one pass, in place."""
        n = len(keys)
        known = np.zeros(n, dtype=bool)
        v, converged, iterations = np.empty(s.shape, dtype=complex), np.empty(n, dtype=bool), np.empty(n, dtype=np.int64)
        table = self._tables.get((net, options))
        if table is None:
            return known, v, converged, iterations
        nowhere = (-1, -1)
        where = np.array([table.get(key, nowhere) for key in keys], dtype=np.int64).reshape(n, 2)  # (batch, row)
        hits = np.flatnonzero(where[:, 0] >= 0)
        if hits.size == 0:
            return known, v, converged, iterations
        words = snapshot_words(s, v0)
        for batch in np.unique(where[hits, 0]).tolist():
            asked = hits[where[hits, 0] == batch]
            kept = where[asked, 1]
            inputs, answers = self._batches[batch][2:4]
            same = same_snapshots(inputs, kept, words, asked)
            asked, kept = asked[same], kept[same]
            known[asked] = True
            v[asked], converged[asked], iterations[asked] = answers[0][kept], answers[1][kept], answers[2][kept]
        return known, v, converged, iterations

    def put(
        self, net: Network, options: Hashable, keys: list[bytes], s: np.ndarray, v0: np.ndarray | None, result: PowerFlowResult
    ) -> None:
        """Remember the answers `result` (copied) of the snapshots `s`, `v0` with digests
        `keys`; the memo keeps `s` and `v0` themselves (made read-only): the caller hands over
        arrays of its own that nothing changes."""
        s_words, v_words = snapshot_words(s, v0)
        size = result.v.nbytes + s_words.nbytes + v_words.nbytes + len(keys) * _ROW_OVERHEAD
        if not keys or size > self.limit // 4:
            return
        table = self._tables.setdefault((net, options), {})
        batch = self._next
        self._next += 1
        for i, key in enumerate(keys):
            table[key] = (batch, i)
        answers = (result.v.copy(), np.array(result.converged, dtype=bool), np.array(result.iterations, dtype=np.int64))
        for kept in (s, v0, s_words, v_words):
            if kept is not None:
                kept.flags.writeable = False
        self._batches[batch] = ((net, options), keys, (s_words, v_words), answers, size)
        self.used += size
        while self.used > self.limit:
            old, (where, old_keys, _, _, old_size) = self._batches.popitem(last=False)
            old_table = self._tables[where]
            for key in old_keys:
                if old_table.get(key, (None,))[0] == old:  # not since answered by a newer batch
                    del old_table[key]
            if not old_table:  # nothing of that network left: let it go
                del self._tables[where]
            self.used -= old_size


def flow_memo() -> FlowMemo:
    """This thread's memo."""
    found: FlowMemo | None = getattr(_local, "memo", None)
    if found is None:
        found = _local.memo = FlowMemo()
    return found


def row_memo() -> RowMemo:
    """This thread's per-snapshot memo."""
    found: RowMemo | None = getattr(_local, "rows", None)
    if found is None:
        found = _local.rows = RowMemo()
    return found


def forget_flows() -> None:
    """Empty this thread's memos (benchmarks timing the flows themselves)."""
    _local.memo = FlowMemo()
    _local.rows = RowMemo()


PROCESS.on_reset("power-flow answers (the calling thread's)", forget_flows)


def cold(fn: Callable[..., T], *args, **kwargs) -> T:
    """`fn(*args, **kwargs)` with this thread's memo emptied first (a benchmark's timed call)."""
    forget_flows()
    return fn(*args, **kwargs)
