"""The batched solver's fixed point V ← Z·conj(S/V) + V₀ on many snapshots at once, with
compiled element-wise passes (numba) around the one linear solve per step (`Z·rhs`: a
BLAS mat-mul on small feeders, SuperLU's solve on large ones).

Each step reads and writes the snapshots still iterating in two fused passes — the
injected currents conj(S)·V/|V|² before the solve, and the update V ← Z·I + V₀ with its
largest squared change |ΔV|² after it — instead of a dozen numpy passes and temporaries
over the whole (buses × snapshots) block; the snapshots that stop (settled below the
tolerance, or a non-finite update) are written out and the others moved to the front, so
the next solve works on the iterating ones only. The arithmetic is numpy's, operation for
operation: numpy's SIMD loops (x86-64) round a complex product as two fused multiply-adds
(re = fma(a.re, b.re, −a.im·b.im), im = fma(a.re, b.im, a.im·b.re)), which the passes
replicate with `llvm.fma`, and nothing else is contracted (no fast-math), so the answers
are the plain numpy iteration's bit for bit (`tests/test_powerflow.py` checks it).

Every snapshot's answer is a function of its own injections alone, whatever else is in
the batch: SuperLU solves column by column, and OpenBLAS's complex mat-mul rounds the
columns of a block's edge (the last columns beyond a multiple of its kernel width) in
other code than the rest, so the dense solve always runs on a multiple of `PAD` columns
(zeros beyond the iterating ones). Sharing one answer among several callers, or solving a
union of snapshots once for several configurations, therefore changes no digit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal, Protocol, cast

import numpy as np
import scipy.sparse as sp
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

PAD = 8  # the dense solve's column count is a multiple of this (OpenBLAS zgemm kernel widths 2, 4, 8)
_BIG = np.finfo(np.float64).max  # |ΔV|² above it (inf) or unordered (NaN): not finite


def _fused_multiply_add(typingctx, a, b, c):
    """numba intrinsic: a·b + c rounded once (IEEE fused multiply-add, `llvm.fma`)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(double, [double] * 3), "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


_fma = cast(Callable[[float, float, float], float], intrinsic(_fused_multiply_add))


@njit(inline="always")
def _current(s: complex, v: complex) -> complex:
    """conj(S/V) from s = conj(S) and V as numpy computes s·V·(1/|V|²): |V|² as re² + im²,
    then two complex products (the real factor as a complex number with a zero
    imaginary part)."""
    r = 1.0 / (v.real * v.real + v.imag * v.imag)
    re = _fma(s.real, v.real, -(s.imag * v.imag))
    im = _fma(s.real, v.imag, s.imag * v.real)
    return complex(_fma(re, r, -(im * 0.0)), _fma(re, 0.0, im * r))


@njit(cache=True)
def _currents(s: np.ndarray, v: np.ndarray, cur: np.ndarray, n: int, width: int, by_column: bool) -> None:
    """cur[:, :n] ← conj(S/V) of the first n columns; columns n … width−1 zeroed."""
    m = v.shape[0]
    if by_column:
        for j in range(n):
            for i in range(m):
                cur[i, j] = _current(s[i, j], v[i, j])
    else:
        for i in range(m):
            for j in range(n):
                cur[i, j] = _current(s[i, j], v[i, j])
    for i in range(m):
        for j in range(n, width):
            cur[i, j] = 0.0


@njit(inline="always")
def _step(zi: np.ndarray, v0: np.ndarray, v: np.ndarray, step2: np.ndarray, finite: np.ndarray, i: int, j: int) -> None:
    """v[i, j] ← zi[i, j] + V₀[i]; step2[j] ← max(step2[j], |ΔV|²), finite[j] cleared by a
    non-finite |ΔV|² (written without branches, so the loops vectorize)."""
    x = zi[i, j] + v0[i]
    d = x - v[i, j]
    e = d.real * d.real + d.imag * d.imag
    s2 = step2[j]
    step2[j] = e if e > s2 else s2
    finite[j] &= e <= _BIG
    v[i, j] = x


@njit(cache=True)
def _update(
    zi: np.ndarray,
    v0: np.ndarray,
    v: np.ndarray,
    s: np.ndarray,
    where: np.ndarray,
    n: int,
    tol2: float,
    it: int,
    by_column: bool,
    keep: np.ndarray,
    out: np.ndarray,
    iterations: np.ndarray,
    settled: np.ndarray,
) -> int:
    """V ← Z·I + V₀ on the first n columns (zi holds Z·I); each column's iteration count
    becomes `it`; a column whose largest |ΔV|² is below tol2 (settled) or not finite (as
    numpy's max over the column would be, NaN or inf) is written to out[snapshot, keep],
    the others are moved to the front (with their S and snapshot number `where`).
    Returns how many still iterate."""
    m = v.shape[0]
    step2, finite = np.zeros(n), np.ones(n, dtype=np.bool_)
    if by_column:
        for j in range(n):
            for i in range(m):
                _step(zi, v0, v, step2, finite, i, j)
    else:
        for i in range(m):
            for j in range(n):
                _step(zi, v0, v, step2, finite, i, j)
    going = 0
    for j in range(n):
        k = where[j]
        iterations[k] = it
        if finite[j] and step2[j] >= tol2:
            where[going] = k
            step2[going] = j  # the column it comes from
            going += 1
            continue
        settled[k] = finite[j]  # and below the tolerance
        for i in range(m):
            out[k, keep[i]] = v[i, j]
    if going < n:
        _compact(v, s, step2, going, by_column)
    return going


@njit(inline="always")
def _compact(v: np.ndarray, s: np.ndarray, source: np.ndarray, n: int, by_column: bool) -> None:
    """Column t of v and s ← column source[t], t < n (source ascending, source[t] ≥ t)."""
    m = v.shape[0]
    if by_column:
        for t in range(n):
            c = int(source[t])
            for i in range(m):
                v[i, t] = v[i, c]
                s[i, t] = s[i, c]
    else:
        for i in range(m):
            for t in range(n):
                c = int(source[t])
                v[i, t] = v[i, c]
                s[i, t] = s[i, c]


@njit(cache=True)
def _write(v: np.ndarray, where: np.ndarray, n: int, keep: np.ndarray, out: np.ndarray) -> None:
    """out[snapshot, keep] ← the first n columns (those still iterating at the limit)."""
    for j in range(n):
        for i in range(v.shape[0]):
            out[where[j], keep[i]] = v[i, j]


@njit(cache=True)
def _mismatch(v: np.ndarray, s: np.ndarray, keep: np.ndarray, indptr, indices, data, out: np.ndarray) -> None:
    """out[k] ← max over the buses `keep` of |V·conj(Y·V) − S| of snapshot k (Y's rows
    `keep` in CSR form); NaN where some is NaN (numpy's max)."""
    for k in range(v.shape[0]):
        worst = 0.0
        for r in range(keep.size):
            current = 0j
            for p in range(indptr[r], indptr[r + 1]):
                current += data[p] * v[k, indices[p]]
            a = abs(v[k, keep[r]] * current.conjugate() - s[k, keep[r]])
            if a > worst or a != a:
                worst = a
        out[k] = worst


def max_mismatch(v: np.ndarray, s: np.ndarray, keep: np.ndarray, y_rows: sp.csr_matrix) -> np.ndarray:
    """(S,) largest |P/Q mismatch| p.u. over the buses `keep` of voltages v (S, n_bus) for
    injections s (S, n_bus) p.u.; `y_rows` = Y[keep, :] (CSR)."""
    out = np.empty(v.shape[0])
    _mismatch(v, s, keep, y_rows.indptr, y_rows.indices, y_rows.data, out)
    return out


class LinearSolve(Protocol):
    """Z = Y[keep, keep]⁻¹ applied to many columns: `apply(rhs, out)` writes Z·rhs for rhs
    (m, n) in memory `order`; `padded`: the solve is a mat-mul whose columns are padded to
    a multiple of PAD (module docstring)."""

    order: Literal["C", "F"]
    padded: bool

    def apply(self, rhs: np.ndarray, out: np.ndarray) -> None: ...


@dataclass
class Sweep:
    """The fixed point's answer: `v` (S, n_bus) with the non-slack columns filled,
    `iterations` (S,), `settled` (S,) bool (the update fell below the tolerance)."""

    v: np.ndarray
    iterations: np.ndarray
    settled: np.ndarray


def fixed_point(
    z: LinearSolve,
    keep: np.ndarray,
    v_noload: np.ndarray,
    s: np.ndarray,
    tol: float,
    max_iter: int,
    v_start: np.ndarray | None,
    out: np.ndarray,
) -> Sweep:
    """Iterate V ← Z·conj(S/V) + V₀ on every snapshot of `s` (S, n_bus) p.u. injections,
    at the non-slack buses `keep`, starting from `v_start` (S, n_bus) or the no-load
    voltages `v_noload` (m,), until each snapshot's largest update is below `tol` p.u. or
    `max_iter` steps; the voltages go to `out` (S, n_bus) at `keep`."""
    n_snap, m, order, padded = s.shape[0], keep.size, z.order, z.padded
    width = -(-n_snap // PAD) * PAD if padded else n_snap
    s_w = np.zeros((m, width), dtype=complex, order=order)
    s_w[:, :n_snap] = np.conj(s[:, keep]).T
    v = np.empty((m, width), dtype=complex, order=order)
    if v_start is None:
        v[:, :n_snap] = v_noload[:, None]
    else:
        v[:, :n_snap] = v_start[:, keep].T
    cur, zi = np.empty_like(v), np.empty_like(v)
    where = np.arange(n_snap)
    sweep = Sweep(out, np.zeros(n_snap, dtype=np.int64), np.zeros(n_snap, dtype=bool))
    by_column = order == "F"
    n = n_snap
    with np.errstate(all="ignore"):
        for it in range(1, max_iter + 1):
            cols = -(-n // PAD) * PAD if padded else n
            _currents(s_w, v, cur, n, cols, by_column)
            z.apply(cur[:, :cols], zi[:, :cols])
            n = _update(zi, v_noload, v, s_w, where, n, tol * tol, it, by_column, keep, out, sweep.iterations, sweep.settled)
            if n == 0:
                return sweep
    _write(v, where, n, keep, out)
    return sweep
