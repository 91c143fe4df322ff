"""Sparse kernels for large feeders (n_bus ≥ SPARSE_MIN_BUSES): the Newton–Raphson
Jacobian as a scipy.sparse CSC matrix factorized by SuperLU (`splu`), and the batched
solver's Z-bus never formed — Y[keep, keep] is factorized once and Z·rhs is
`lu.solve(rhs)` on all snapshots' columns. Memory grows linearly with the bus count
(a radial feeder's matrices factorize with little fill-in)."""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from opfbench.network import Network
from opfbench.powerflow.common import bus_types

# The Jacobian and Y have a symmetric sparsity pattern: SuperLU's symmetric mode (minimum
# degree on A + Aᵀ, diagonal pivots preferred unless 100× smaller than the column's
# largest entry) factorizes them with little fill-in, faster than the default COLAMD with
# unrestricted partial pivoting on the 10 000-bus feeder (`python -m opfbench.bench pf --large`).
_SPLU_OPTIONS = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.01, "options": {"SymmetricMode": True}}


def factorize(a: sp.spmatrix):
    """SuperLU factors of a square sparse matrix with a symmetric pattern."""
    return splu(sp.csc_matrix(a), **_SPLU_OPTIONS)


class SparseNewton:
    """Polar Newton–Raphson system of one network with the sparse Jacobian.

    The Jacobian's pattern is fixed by Y's, so it is assembled once: each Y entry (i, j)
    contributes dS_i/dVa_j to the ΔP (i ∈ pvpq) and ΔQ (i ∈ pq) rows and dS_i/dVm_j to
    the |V| columns (j ∈ pq). Every iteration only refills the CSC data array from the
    MATPOWER `dSbus_dV` values of the Y entries.
    """

    def __init__(self, net: Network) -> None:
        self.pv, self.pq, self.pvpq = bus_types(net)
        n_bus, n, n_pq = net.n_bus, len(self.pvpq), len(self.pq)
        y = net.ybus_sparse.tocoo()
        self.i, self.j, self.y = y.row.astype(np.int64), y.col.astype(np.int64), y.data
        self.is_diag = self.i == self.j
        self.y_rows = net.ybus_sparse[self.pvpq]  # CSR rows pvpq, for the mismatch
        pos_a = np.full(n_bus, -1)
        pos_a[self.pvpq] = np.arange(n)
        pos_m = np.full(n_bus, -1)
        pos_m[self.pq] = np.arange(n_pq)
        # Four blocks: (rows, cols, which entries, takes Va or Vm derivative, real or imag).
        blocks = []
        for row_pos, row_off, part in ((pos_a, 0, "real"), (pos_m, n, "imag")):
            for col_pos, col_off, wrt in ((pos_a, 0, "va"), (pos_m, n, "vm")):
                sel = np.flatnonzero((row_pos[self.i] >= 0) & (col_pos[self.j] >= 0))
                blocks.append((row_pos[self.i[sel]] + row_off, col_pos[self.j[sel]] + col_off, sel, wrt, part))
        rows = np.concatenate([b[0] for b in blocks])
        cols = np.concatenate([b[1] for b in blocks])
        self._blocks = [(b[2], b[3], b[4]) for b in blocks]
        size = n + n_pq
        # Order of the assembled entries inside the CSC data array (no duplicates).
        order = sp.csc_matrix((np.arange(1, len(rows) + 1, dtype=float), (rows, cols)), shape=(size, size))
        self._perm = order.data.astype(np.int64) - 1
        self._indices, self._indptr, self._shape = order.indices, order.indptr, order.shape

    def mismatch(self, v: np.ndarray, s_sub: np.ndarray) -> np.ndarray:
        """[ΔP at pvpq, ΔQ at pq] p.u. for voltages v (n_bus,) and injections s_sub at pvpq."""
        mis = v[self.pvpq] * np.conj(self.y_rows @ v) - s_sub
        return np.concatenate([mis.real, mis.imag[len(self.pv) :]])

    def jacobian(self, v: np.ndarray) -> sp.csc_matrix:
        """The polar power-flow Jacobian at v (CSC)."""
        vi, vj = v[self.i], v[self.j]
        yv = self.y * vj
        ibus = np.bincount(self.i, weights=yv.real, minlength=len(v)) + 1j * np.bincount(
            self.i, weights=yv.imag, minlength=len(v)
        )
        vnorm_j = vj / np.abs(vj)
        # MATPOWER dSbus_dV: dS/dVa = j·diag(V)·conj(diag(I) − Y·diag(V)),
        # dS/dVm = diag(V)·conj(Y·diag(V/|V|)) + conj(diag(I))·diag(V/|V|).
        ds_dva = -1j * vi * np.conj(yv)
        ds_dvm = vi * np.conj(self.y * vnorm_j)
        d = self.is_diag
        ds_dva[d] += 1j * vi[d] * np.conj(ibus[self.i[d]])
        ds_dvm[d] += np.conj(ibus[self.i[d]]) * vnorm_j[d]
        parts = []
        for sel, wrt, part in self._blocks:
            vals = (ds_dva if wrt == "va" else ds_dvm)[sel]
            parts.append(vals.real if part == "real" else vals.imag)
        data = np.concatenate(parts)[self._perm]
        return sp.csc_matrix((data, self._indices, self._indptr), shape=self._shape)

    def step(self, v: np.ndarray, f: np.ndarray) -> np.ndarray | None:
        """Newton step [ΔVa at pvpq, ΔVm at pq] solving J·dx = −f; None if J is singular."""
        try:
            return factorize(self.jacobian(v)).solve(-f)
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            return None


class SparseZbus:
    """Y[keep, keep] factorized once by SuperLU; `apply` solves for all columns at once."""

    def __init__(self, net: Network, keep: np.ndarray) -> None:
        y = net.ybus_sparse
        self.lu = factorize(y[keep][:, keep])

    order: Literal["C", "F"] = "F"  # column-major: SuperLU's solve reads and writes Fortran arrays
    padded = False  # SuperLU solves column by column

    def apply(self, rhs: np.ndarray, out: np.ndarray) -> None:
        """out ← Y[keep, keep]⁻¹·rhs for rhs (m, S)."""
        out[...] = self.lu.solve(rhs)
