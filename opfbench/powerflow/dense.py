"""Dense kernels for small feeders (n_bus < SPARSE_MIN_BUSES): the Newton–Raphson
Jacobian as a dense matrix (`np.linalg.solve`) and the batched solver's Z-bus as the
explicit inverse of the reduced admittance matrix (one mat-mul per fixed-point step)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.linalg import lapack

from opfbench.network import Network
from opfbench.powerflow.common import bus_types


class DenseNewton:
    """Polar Newton–Raphson system of one network: mismatch and Newton step, dense."""

    def __init__(self, net: Network) -> None:
        self.pv, self.pq, self.pvpq = bus_types(net)
        y = net.ybus
        self.y_rows = y[self.pvpq]  # Y[pvpq, :]
        self.y_sub_conj = np.conj(y[np.ix_(self.pvpq, self.pvpq)])
        n = len(self.pvpq)
        # Fortran order: LAPACK's dgesv factors it in place, no copy (np.linalg.solve costs
        # ~7 µs more per step on paper33: `python -m opfbench.bench pf`, single_ms).
        self._jac = np.empty((n + len(self.pq), n + len(self.pq)), order="F")

    def mismatch(self, v: np.ndarray, s_sub: np.ndarray) -> np.ndarray:
        """[ΔP at pvpq, ΔQ at pq] p.u. for voltages v (n_bus,) and injections s_sub at pvpq."""
        mis = v[self.pvpq] * np.conj(self.y_rows @ v) - s_sub
        return np.concatenate([mis.real, mis.imag[len(self.pv) :]])

    def step(self, v: np.ndarray, f: np.ndarray) -> np.ndarray | None:
        """Newton step [ΔVa at pvpq, ΔVm at pq] solving J·dx = −f; None if J is singular."""
        n_pv, n = len(self.pv), len(self.pvpq)
        vs = v[self.pvpq]
        ibus = self.y_rows @ v
        vnorm = vs / np.abs(vs)
        # dS/dVa and dS/dVm restricted to rows and columns pvpq (MATPOWER dSbus_dV).
        vy = vs[:, None] * self.y_sub_conj
        ds_dva = vy * (-1j * np.conj(vs))  # = −j·vy·conj(vs), bit for bit, one n² product less
        ds_dva.reshape(-1)[:: n + 1] += 1j * vs * np.conj(ibus)  # the diagonal
        ds_dvm = vy * np.conj(vnorm)
        ds_dvm.reshape(-1)[:: n + 1] += np.conj(ibus) * vnorm
        jac = self._jac
        jac[:n, :n] = ds_dva.real
        jac[:n, n:] = ds_dvm[:, n_pv:].real
        jac[n:, :n] = ds_dva[n_pv:].imag
        jac[n:, n:] = ds_dvm[n_pv:, n_pv:].imag
        _, _, dx, info = lapack.dgesv(jac, -f, overwrite_a=True, overwrite_b=True)
        return dx if info == 0 else None  # info > 0: J is singular


class DenseZbus:
    """Z = Y[keep, keep]⁻¹ as a dense matrix; `apply` is one mat-mul."""

    def __init__(self, net: Network, keep: np.ndarray) -> None:
        y = net.ybus
        self.z = np.linalg.inv(y[np.ix_(keep, keep)])

    order: Literal["C", "F"] = "C"  # row-major: the mat-mul writes into `out` directly
    padded = True  # a mat-mul: the fixed point pads its columns (`fixed_point.PAD`)

    def apply(self, rhs: np.ndarray, out: np.ndarray) -> None:
        """out ← Z·rhs for rhs (m, S)."""
        np.matmul(self.z, rhs, out=out)
