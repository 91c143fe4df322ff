"""Where the physical limit of a relaxation answer lies: the size of the conic program
Clarabel solves per snapshot, the sparse LDLᵀ factorization each of its iterations needs,
its flops, and how far Clarabel's time per iteration is from that factorization alone.

Clarabel solves A·x + s = b, s ∈ K by a primal-dual interior-point method; each iteration
factors the quasidefinite KKT matrix

    K = [ P + δI    Aᵀ        ]
        [ A        −(WᵀW + δI) ]

(W: the cones' scaling — diagonal on the zero and nonnegative rows, a dense d×d block per
second-order cone of dimension d ≤ 4, as DistFlow's are) and solves with it twice
(the affine and the combined step; iterative refinement is off, `relaxation_settings`).
`kkt_pattern` builds K's pattern with values that keep it quasidefinite; the peer is the
work an iteration cannot avoid, timed in the same process: K re-factored and solved with
twice by QDLDL's algorithm (the LDLᵀ Clarabel runs, `ldl_factor`, compiled with numba),
on K permuted by the AMD ordering of QDLDL's C library (`qdldl`, a dependency of cvxpy,
whose own Python `update` spends most of its time outside the factorization).

Flops of one factorization: Σⱼ cⱼ·(cⱼ + 3) with cⱼ the nonzeros below the diagonal in
column j of L (the count of George & Liu for a sparse Cholesky factor, multiplications
and additions); of one solve with L·D·Lᵀ: 4·nnz(L) + dim. The figures are of the full
program; on feeders with bound screening (`models.conic.screens`) most answers come from
a smaller screened program, and `iterations_median` / `iteration_us` are of whatever
program answered.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from numba import njit

from opfbench.formulations.solvers.clarabel_adapter import ParametricConeProgram


def ldl_etree(n: int, ap: np.ndarray, ai: np.ndarray, lnz: np.ndarray, etree: np.ndarray) -> None:
    """QDLDL's elimination tree of an upper-triangular CSC matrix (ap, ai): `etree` and
    the nonzeros `lnz` per column of L (filled in; once per pattern, not timed)."""
    work = np.zeros(n, dtype=np.int64)
    for i in range(n):
        lnz[i] = 0
        etree[i] = -1
    for j in range(n):
        work[j] = j
        for p in range(ap[j], ap[j + 1]):
            i = ai[p]
            while work[i] != j:
                if etree[i] == -1:
                    etree[i] = j
                lnz[i] += 1
                work[i] = j
                i = etree[i]


@njit(cache=True)
def ldl_factor(n, ap, ai, ax, lp, li, lx, d, lnz, etree) -> None:  # pragma: no cover (numba)
    """QDLDL's numeric LDLᵀ factorization (up-looking, by rows of L) of the upper-triangular
    CSC matrix (ap, ai, ax) into (lp, li, lx) and d, given `ldl_etree`'s lnz and etree."""
    marked = np.zeros(n, dtype=np.bool_)
    y_idx = np.zeros(n, dtype=np.int64)
    buffer = np.zeros(n, dtype=np.int64)
    next_space = np.zeros(n, dtype=np.int64)
    y = np.zeros(n)
    dinv = np.zeros(n)
    lp[0] = 0
    for i in range(n):
        lp[i + 1] = lp[i] + lnz[i]
        next_space[i] = lp[i]
    d[0] = ax[0]
    dinv[0] = 1.0 / d[0]
    for k in range(1, n):
        n_y = 0
        for p in range(ap[k], ap[k + 1]):
            b = ai[p]
            if b == k:
                d[k] = ax[p]
                continue
            y[b] = ax[p]
            if not marked[b]:
                marked[b] = True
                buffer[0] = b
                n_e = 1
                nxt = etree[b]
                while nxt != -1 and nxt < k:
                    if marked[nxt]:
                        break
                    marked[nxt] = True
                    buffer[n_e] = nxt
                    n_e += 1
                    nxt = etree[nxt]
                while n_e:
                    n_e -= 1
                    y_idx[n_y] = buffer[n_e]
                    n_y += 1
        for i in range(n_y - 1, -1, -1):
            c = y_idx[i]
            end = next_space[c]
            yc = y[c]
            for j in range(lp[c], end):
                y[li[j]] -= lx[j] * yc
            li[end] = k
            lx[end] = yc * dinv[c]
            d[k] -= yc * lx[end]
            next_space[c] += 1
            y[c] = 0.0
            marked[c] = False
        dinv[k] = 1.0 / d[k]


@njit(cache=True)
def ldl_solve(n, lp, li, lx, d, x) -> None:  # pragma: no cover (numba)
    """x ← (L·D·Lᵀ)⁻¹·x in place (`ldl_factor`'s factors)."""
    for i in range(n):
        for j in range(lp[i], lp[i + 1]):
            x[li[j]] -= lx[j] * x[i]
    for i in range(n):
        x[i] /= d[i]
    for i in range(n - 1, -1, -1):
        for j in range(lp[i], lp[i + 1]):
            x[i] -= lx[j] * x[li[j]]


class Ldl:
    """QDLDL's LDLᵀ of a symmetric matrix `k` (CSC) under the permutation `perm`: the
    pattern analysed once, `factor` re-factors, `solve` solves (numba-compiled)."""

    def __init__(self, k: sp.csc_matrix, perm: np.ndarray):
        upper = sp.triu(k[perm][:, perm], format="csc")
        upper.sort_indices()
        self.n = n = upper.shape[0]
        self.ap, self.ai = upper.indptr.astype(np.int64), upper.indices.astype(np.int64)
        self.ax = upper.data.astype(float)
        self.lnz, self.etree = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        ldl_etree(n, self.ap, self.ai, self.lnz, self.etree)
        self.lp = np.zeros(n + 1, dtype=np.int64)
        total = int(self.lnz.sum())
        self.li, self.lx, self.d = np.zeros(total, dtype=np.int64), np.zeros(total), np.zeros(n)

    def factor(self) -> None:
        ldl_factor(self.n, self.ap, self.ai, self.ax, self.lp, self.li, self.lx, self.d, self.lnz, self.etree)

    def solve(self, x: np.ndarray) -> np.ndarray:
        x = np.array(x, dtype=float)
        ldl_solve(self.n, self.lp, self.li, self.lx, self.d, x)
        return x


def kkt_pattern(program: ParametricConeProgram) -> sp.csc_matrix:
    """The full program's KKT matrix K (module docstring), symmetric, with values that
    keep it quasidefinite (the factorization's cost depends on the pattern alone)."""
    a = program.full_a
    m, n = a.shape
    soc = list(program.cone_dims.soc)
    blocks = [sp.identity(m - sum(soc), format="csc")] + [sp.csc_matrix(np.full((d, d), 0.1) + 0.9 * np.eye(d)) for d in soc]
    w = sp.block_diag(blocks, format="csc")
    p = program.objective.p
    p = p + p.T - sp.diags(p.diagonal())  # P is stored upper triangular
    k = sp.bmat([[p + 10.0 * sp.identity(n), a.T], [a, -10.0 * w]], format="csc")
    k.sum_duplicates()
    return k


def factor_flops(column_counts: np.ndarray) -> float:
    """Flops of a sparse LDLᵀ (Cholesky) factorization with `column_counts` nonzeros below
    the diagonal per column of L (module docstring)."""
    c = np.asarray(column_counts, dtype=float)
    return float(np.sum(c * (c + 3.0)))


def kkt_figures(program: ParametricConeProgram, offsets: np.ndarray, repeats: int = 200) -> dict:
    """The full program's dimensions, KKT nonzeros, fill and flops; Clarabel's iterations
    and CPU time per iteration on the full program over the snapshots `offsets` (rows of
    `program.offsets`), and an answer's CPU time as the runner gets it (`program.solve`:
    screened where the feeder screens); and the peer: K re-factored and solved with twice
    (`Ldl`, `repeats` times, median). CPU time (`time.process_time`): the machine may be
    shared."""
    import qdldl

    k = kkt_pattern(program)
    dim = k.shape[0]
    _, _, perm = qdldl.Solver(k).factors()  # its AMD ordering
    ldl = Ldl(k, np.asarray(perm))
    counts = ldl.lnz
    nnz_l = int(counts.sum())
    rhs = np.ones(dim)
    ldl.factor()
    ldl.solve(rhs)  # compiled before timing
    peer = []
    for _ in range(repeats):
        start = time.process_time()
        ldl.factor()
        ldl.solve(ldl.solve(rhs))
        peer.append(time.process_time() - start)
    per_iteration, iterations, answer_ms = [], [], []
    for b in offsets:
        start = time.process_time()
        _, _, n_iter = program.full.solve(b)
        cpu = time.process_time() - start
        iterations.append(n_iter)
        per_iteration.append(1e6 * cpu / max(n_iter, 1))
    for b in offsets:  # the answers as the runner gets them (screened where the feeder screens)
        start = time.process_time()
        program.solve(b)
        answer_ms.append(1e3 * (time.process_time() - start))
    flops = factor_flops(counts)
    ldl_us = 1e6 * float(np.median(peer))
    iteration_us = float(np.median(per_iteration))
    nnz_k = int(sp.triu(k).nnz)
    return {
        "variables": int(program.n_x),
        "rows": int(program.full_a.shape[0]),
        "soc_cones": len(program.cone_dims.soc),
        "kkt_dim": int(dim),
        "kkt_nnz": nnz_k,  # upper triangle with the diagonal
        "ldl_nnz": nnz_l,  # below the diagonal of L
        "fill": (nnz_l + dim) / nnz_k,
        "factor_kflop": flops / 1e3,
        "iteration_kflop": (flops + 2 * (4 * nnz_l + dim)) / 1e3,
        "iterations_median": float(np.median(iterations)),  # Clarabel on the full program
        "iteration_us": iteration_us,  # its CPU per iteration, median over the snapshots
        "answer_ms_median": float(np.median(answer_ms)),  # an answer as the runner gets it (screened or not)
        "ldl_us": ldl_us,
        "iteration_over_ldl": iteration_us / ldl_us,
        "ldl_gflops": (flops + 2 * (4 * nnz_l + dim)) / (ldl_us * 1e3),
    }
