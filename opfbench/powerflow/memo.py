"""Batched power flows remembered snapshot by snapshot, per thread.

A study runs the same flows more than once: every closed-loop local rule starts from the
no-action state (the `no-action` strategy's own flow), the `socp` strategy evaluates the
setpoints whose flow the AC OPF's fast path has just solved, and a closed-loop rule whose
iteration retraces another's (Volt-VAR with a Volt-Watt that never acts, a reserve k whose
limit never binds, a night hour that no night mode changes) asks again for snapshots
another has solved. Each snapshot's answer is a function of its own injections and warm
start alone, whatever else is in the batch (`fixed_point`), and of the network and options,
so `FlowMemo` remembers the answers per snapshot: a batch gets the voltages, verdict and
iteration count of the snapshots this thread solved recently, and only the others are
solved — a batch asked again whole is not solved at all.

A snapshot is looked up by a 64-bit digest of its exact bytes (injections, and warm start
or its absence; `row_digests`) under its network and options, and confirmed against the
remembered snapshot's bytes, so no two different snapshots can share an answer, however
their digests fall. Look-ups and insertions run on a whole batch at once (a compiled
open-addressing table: no Python step per snapshot). At most MEMO_BYTES of snapshots and
answers are kept per thread (oldest batches dropped first). Benchmarks that time a flow on
the same input again call `forget_flows` first.
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
MEMO_BYTES = 768 * 2**20  # per thread: the snapshots and answers kept (the snapshots take 1–2× the answers)
_ROW_OVERHEAD = 160  # bytes per remembered snapshot beyond its voltages and injections (its table slots: 4–8 of 16 bytes)
_ROW_BITS = 32  # a table entry: batch << _ROW_BITS | row

_local = threading.local()


_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_SEED = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, inline="always")
def _mix(z):
    """splitmix64's finalizer: a bijection of 64-bit words in which every input bit moves
    every output bit."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _sum(words: np.ndarray, h, offset: int):
    """`h` plus `_mix` of each of `words` keyed by its position (from `offset`): each word's
    term is independent of the others' (no chain to wait on), and a change of any one word
    changes the sum (`_mix` is a bijection)."""
    for j in range(words.size):
        h += _mix(words[j] ^ (np.uint64(offset + j + 1) * _SEED))
    return h


@njit(cache=True)
def _digests(s_words: np.ndarray, v_words: np.ndarray, tag: np.uint64, out: np.ndarray) -> None:
    """out[i] ← the sum (`_sum`) over row i of `s_words` then of `v_words` (S, w) uint64,
    started from `tag`, mixed once more."""
    for i in range(s_words.shape[0]):
        out[i] = _mix(_sum(v_words[i], _sum(s_words[i], tag, 0), s_words.shape[1]))


def row_digests(s: np.ndarray, v0: np.ndarray | None) -> np.ndarray:
    """A 64-bit digest (S,) uint64 of each snapshot's exact bytes: its injections `s`
    (S, n) complex and warm start `v0` (S, n) complex, or the absence of one (`FlowMemo`);
    both C-contiguous."""
    s_words, v_words = snapshot_words(s, v0)
    out = np.empty(s.shape[0], dtype=np.uint64)
    _digests(s_words, v_words, np.uint64(0 if v0 is None else 1), out)
    return out


@njit(cache=True, inline="always")
def _probe(keys: np.ndarray, entries: np.ndarray, key) -> np.int64:
    """The slot of `key` in the open-addressing table (`keys`, `entries`; linear probing,
    a power-of-two size, never full): its own, or the empty one (entry -1) where it would go."""
    mask = keys.size - 1
    slot = np.int64(key & np.uint64(mask))  # a digest's low bits are as mixed as its others
    while entries[slot] >= 0 and keys[slot] != key:
        slot = (slot + 1) & mask
    return slot


def _slots(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty keys and entries of a table (`_probe`) at most a quarter full with `n` entries."""
    size = 1 << max(6, (4 * n - 1).bit_length())
    return np.zeros(size, dtype=np.uint64), np.full(size, -1, dtype=np.int64)


class _Table:
    """An open-addressing table (`_probe`) of digests → entries `batch << _ROW_BITS | row`,
    at most half full. The entries of dropped batches (older than the memo's oldest) are
    stale: never found, left in place until the table is rebuilt as it grows."""

    def __init__(self, n: int) -> None:
        self.keys, self.entries = _slots(n)
        self.filled, self.newest = 0, -1  # slots in use; the newest batch entered

    def look(self, digests: np.ndarray, oldest: int) -> np.ndarray:
        """The live entry (S,) of each of `digests`, or -1."""
        out = np.empty(digests.size, dtype=np.int64)
        _look(self.keys, self.entries, digests, oldest, out)
        return out

    def enter(self, digests: np.ndarray, batch: int, oldest: int) -> None:
        """Enter the rows of `batch` under their `digests` (a digest already there: its newer
        answer); rebuilt from the live entries, at most a quarter full, when it would be over
        half full."""
        if 2 * (self.filled + digests.size) > self.keys.size:
            old = self.keys, self.entries
            self.keys, self.entries = _slots(int(np.count_nonzero(old[1] >> _ROW_BITS >= oldest)) + digests.size)
            self.filled = _rehash(*old, oldest, self.keys, self.entries)
        self.filled += _enter(self.keys, self.entries, digests, batch << _ROW_BITS)
        self.newest = batch


@njit(cache=True)
def _look(keys: np.ndarray, entries: np.ndarray, digests: np.ndarray, oldest: int, out: np.ndarray) -> None:
    """out[i] ← the live entry of digests[i], or -1 (`_Table.look`)."""
    for i in range(digests.size):
        entry = entries[_probe(keys, entries, digests[i])]
        out[i] = entry if entry >= 0 and entry >> _ROW_BITS >= oldest else -1


@njit(cache=True)
def _enter(keys: np.ndarray, entries: np.ndarray, digests: np.ndarray, first: int) -> int:
    """Enter digests[i] → first + i; the number of slots newly in use."""
    filled = 0
    for i in range(digests.size):
        slot = _probe(keys, entries, digests[i])
        if entries[slot] < 0:
            filled += 1
        keys[slot], entries[slot] = digests[i], first + i
    return filled


@njit(cache=True)
def _rehash(keys: np.ndarray, entries: np.ndarray, oldest: int, new_keys: np.ndarray, new_entries: np.ndarray) -> int:
    """Enter the live entries of a table into an empty one; their number."""
    filled = 0
    for j in range(keys.size):
        if entries[j] >= 0 and entries[j] >> _ROW_BITS >= oldest:
            slot = _probe(new_keys, new_entries, keys[j])
            new_keys[slot], new_entries[slot] = keys[j], entries[j]
            filled += 1
    return filled


@njit(cache=True)
def _first_rows(digests: np.ndarray, keys: np.ndarray, entries: np.ndarray, out: np.ndarray) -> None:
    """out[i] ← the first row with digests[i], by an empty table (`first_rows`)."""
    for i in range(digests.size):
        slot = _probe(keys, entries, digests[i])
        if entries[slot] < 0:
            keys[slot], entries[slot] = digests[i], i
        out[i] = entries[slot]


def first_rows(digests: np.ndarray) -> np.ndarray:
    """For each of `digests` (S,) uint64 the first row (S,) that has it."""
    out = np.empty(digests.size, dtype=np.int64)
    _first_rows(digests, *_slots(digests.size), out)
    return out


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


# a remembered batch: (network, options), snapshots (`snapshot_words`), answers, bytes
_Batch = tuple[tuple, tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], int]


class FlowMemo:
    """The per-snapshot answers of one thread (module docstring): `find` the remembered
    answers of some snapshots, `put` those of freshly solved ones; batches of answers are
    dropped oldest first beyond `limit_bytes`. A snapshot found by its digest is served only
    if its bytes are those of the remembered snapshot (kept with its answer), so no two
    different snapshots can share an answer, however their digests fall."""

    def __init__(self, limit_bytes: int = MEMO_BYTES):
        self.limit, self.used = limit_bytes, 0
        self._tables: dict[tuple, _Table] = {}  # (network, options) → its snapshots' digests
        self._batches: OrderedDict[int, _Batch] = OrderedDict()
        self._next = self._oldest = 0  # batches are numbered in order, and dropped in order

    def find(
        self, net: Network, options: Hashable, digests: np.ndarray, s: np.ndarray, v0: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Which snapshots (`digests` of injections `s` (S, n) and warm start `v0`, as
        `row_digests`) have a remembered answer: a mask (S,), and arrays of voltages (S, n),
        converged (S,) and iterations (S,) holding those answers in their rows — the other
        rows are for the caller to fill. Each batch's hits are confirmed in one pass, in place."""
        n = digests.size
        known = np.zeros(n, dtype=bool)
        v, converged, iterations = np.empty(s.shape, dtype=complex), np.empty(n, dtype=bool), np.empty(n, dtype=np.int64)
        table = self._tables.get((net, options))
        if table is None:
            return known, v, converged, iterations
        entries = table.look(digests, self._oldest)
        hits = np.flatnonzero(entries >= 0)
        if hits.size == 0:
            return known, v, converged, iterations
        words = snapshot_words(s, v0)
        batches, rows = entries >> _ROW_BITS, entries & ((1 << _ROW_BITS) - 1)
        for batch in np.unique(batches[hits]).tolist():
            asked = hits[batches[hits] == batch]
            kept = rows[asked]
            inputs, answers = self._batches[batch][1:3]
            same = same_snapshots(inputs, kept, words, asked)
            asked, kept = asked[same], kept[same]
            known[asked] = True
            v[asked], converged[asked], iterations[asked] = answers[0][kept], answers[1][kept], answers[2][kept]
        return known, v, converged, iterations

    def put(
        self,
        net: Network,
        options: Hashable,
        digests: np.ndarray,
        s: np.ndarray,
        v0: np.ndarray | None,
        result: PowerFlowResult,
    ) -> None:
        """Remember the answers `result` (copied) of the snapshots `s`, `v0` with `digests`;
        the memo keeps `s` and `v0` themselves (made read-only): the caller hands over arrays
        of its own that nothing changes."""
        s_words, v_words = snapshot_words(s, v0)
        size = result.v.nbytes + s_words.nbytes + v_words.nbytes + digests.size * _ROW_OVERHEAD
        if not digests.size or size > self.limit // 4:
            return
        where = (net, options)
        batch = self._next
        self._next += 1
        table = self._tables.get(where)
        if table is None:
            table = self._tables[where] = _Table(digests.size)
        table.enter(digests, batch, self._oldest)
        answers = (result.v.copy(), np.array(result.converged, dtype=bool), np.array(result.iterations, dtype=np.int64))
        for kept in (s, v0, s_words, v_words):
            if kept is not None:
                kept.flags.writeable = False
        self._batches[batch] = (where, (s_words, v_words), answers, size)
        self.used += size
        while self.used > self.limit:
            old, (old_where, _, _, old_size) = self._batches.popitem(last=False)
            self._oldest = old + 1
            if self._tables[old_where].newest < self._oldest:  # nothing of that network left: let it go
                del self._tables[old_where]
            self.used -= old_size


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
