"""Loads and DER as branches between two nodes, and OpenDSS's load models as one current
function.

A load or DER element of p phases is p branches a → b, each carrying 1/p of the element's
power (OpenDSS's rule: "the load is assumed balanced over the no. of phases defined"):

- wye: phase node → the element's neutral (its last conductor: ground, or a neutral node);
- delta: phase node i → phase node i+1 (the last wraps to the first); a one-phase delta
  element is one branch between its two nodes.

Each branch has a base voltage: for wye elements of two or three phases the element's
kV/√3, for every other element (delta, one-phase wye) its kV — OpenDSS's
`UpdateVoltageBases`. The voltage across a branch in p.u. of that base is what a load
model, and a DER's own voltage measurement, reads.

Signs: a load branch *draws* its current from node a into node b (power positive =
consumed); a DER branch *injects* (power positive = generated). Units: V, A, W, var.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

GROUND = -1
"""Node index of ground (OpenDSS's node 0): a branch to ground has b = GROUND."""

CONSTANT_PQ, CONSTANT_Z, EXPONENTIAL, CONSTANT_I = 1, 2, 4, 5
LOAD_MODELS = {
    CONSTANT_PQ: "constant P and Q",
    CONSTANT_Z: "constant impedance",
    EXPONENTIAL: "exponential (CVR factors)",
    CONSTANT_I: "constant current magnitude",
}
"""OpenDSS load models opfbench evaluates (`Load.model`); others are refused by the reader."""


def _frozen(arr: object) -> np.ndarray:
    arr = np.array(arr)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Branches:
    """Elements (loads or DER) as branches. Arrays (n_branch,): `owner` the element's index,
    `a` the phase node, `b` the other node (GROUND, a neutral or another phase), `vbase_v`
    the branch's base voltage (V), `share` the element's power fraction on it (1/phases).
    `n_owner` elements in all (an element may have no branch only if it has no phase)."""

    owner: np.ndarray
    a: np.ndarray
    b: np.ndarray
    vbase_v: np.ndarray
    share: np.ndarray
    n_owner: int

    def __post_init__(self) -> None:
        for name, kind in (("owner", int), ("a", int), ("b", int), ("vbase_v", float), ("share", float)):
            object.__setattr__(self, name, _frozen(np.asarray(getattr(self, name), dtype=kind)))

    @classmethod
    def empty(cls) -> "Branches":
        return cls(np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), np.zeros(0), np.zeros(0), 0)

    @property
    def n(self) -> int:
        return len(self.a)

    def incidence(self, n_node: int) -> sp.csr_matrix:
        """(n_node, n_branch) +1 at node a, −1 at node b (none at ground): a current
        injected *into a* by the branch is `incidence @ current`."""
        cols = np.arange(self.n)
        to = self.b != GROUND
        rows = np.concatenate([self.a, self.b[to]])
        vals = np.concatenate([np.ones(self.n), -np.ones(int(to.sum()))])
        return sp.csr_matrix((vals, (rows, np.concatenate([cols, cols[to]]))), shape=(n_node, self.n))


@dataclass(frozen=True, eq=False)
class LoadModels:
    """OpenDSS's voltage dependence of each load element (arrays (n_load,)): `model` 1
    constant P and Q, 2 constant impedance, 4 exponential (P ∝ u^cvr_p, Q ∝ u^cvr_q,
    OpenDSS's CVRwatts/CVRvars), 5 constant current magnitude; u = |V_branch|/V_base.

    Models 1, 4 and 5 hold their law for vminpu < u ≤ vmaxpu and switch, as OpenDSS does,
    to an impedance outside it: above vmaxpu the admittance that gives the nominal power
    at vmaxpu (model 5: the nominal current); from vminpu down to vlowpu a current
    magnitude falling linearly to that of the nominal impedance at vlowpu; below vlowpu
    the nominal impedance. Model 2 is an impedance everywhere. The nominal impedance is
    the one that draws the element's present power (its profile value) at u = 1.
    """

    model: np.ndarray
    vminpu: np.ndarray
    vmaxpu: np.ndarray
    vlowpu: np.ndarray
    cvr_p: np.ndarray
    cvr_q: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "model", _frozen(np.asarray(self.model, dtype=int)))
        for name in ("vminpu", "vmaxpu", "vlowpu", "cvr_p", "cvr_q"):
            object.__setattr__(self, name, _frozen(np.asarray(getattr(self, name), dtype=float)))

    @classmethod
    def empty(cls) -> "LoadModels":
        z = np.zeros(0)
        return cls(np.zeros(0, int), z, z, z, z, z)

    def branch_law(self, owner: np.ndarray) -> "BranchLaw":
        """The per-branch constants of the current function (`BranchLaw`, `drawn`)."""
        model = self.model[owner]
        exp_p = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], self.cvr_p[owner])
        exp_q = np.select([model == CONSTANT_PQ, model == CONSTANT_Z, model == CONSTANT_I], [0.0, 2.0, 1.0], self.cvr_q[owner])
        vmin, vmax, vlow = self.vminpu[owner], self.vmaxpu[owner], self.vlowpu[owner]
        constant_i = model == CONSTANT_I
        return BranchLaw(
            exp_p - 1.0,
            exp_q - 1.0,
            model != CONSTANT_Z,
            vmin,
            vmax,
            vlow,
            np.where(constant_i, 1.0, 1.0 / np.where(vmin > 0, vmin, 1.0)),
            np.where(constant_i, vmax, vmax**2),
        )


@dataclass(frozen=True, eq=False)
class BranchLaw:
    """Per-branch constants (n_branch,) of the load branches' current (`drawn`): in-band
    exponents of u for the P and Q parts of the current (law exponent − 1), whether the
    branch switches to impedances outside [vminpu, vmaxpu], the limits, the current factor
    at vminpu and the divisor of u above vmaxpu."""

    h_p: np.ndarray
    h_q: np.ndarray
    switches: np.ndarray
    vmin: np.ndarray
    vmax: np.ndarray
    vlow: np.ndarray
    at_vmin: np.ndarray
    above_div: np.ndarray

    @property
    def constants(self) -> tuple[np.ndarray, ...]:
        """The constants in `drawn`'s order (after the branch's voltage, powers and base)."""
        return (self.h_p, self.h_q, self.switches, self.vmin, self.vmax, self.vlow, self.at_vmin, self.above_div)


@njit(cache=True, error_model="numpy")
def drawn(
    v: complex,
    p_w: float,
    q_var: float,
    vbase_v: float,
    h_p: float,
    h_q: float,
    switches: bool,
    vmin: float,
    vmax: float,
    vlow: float,
    at_vmin: float,
    above_div: float,
) -> complex:
    """The current (complex A) a load branch draws from node a into node b at the voltage
    `v` across it (complex V), for its powers p_w, q_var (W, var) at its law's reference
    (u = 1), its base voltage and its law's constants (`BranchLaw`):

        I = (P·h_P(u) − j·Q·h_Q(u))·e^{jθ}/V_base,   u = |V|/V_base, θ = arg V,

    h = u^(exponent − 1) in band, and the impedance switches of `LoadModels` outside."""
    re, im = v.real, v.imag
    mag = np.sqrt(re * re + im * im)
    per_base = 1.0 / vbase_v
    u = mag * per_base
    if mag > 0:
        per_mag = 1.0 / mag
        re, im = re * per_mag, im * per_mag
    else:
        per_mag = np.inf
        re, im = 1.0, 0.0
    hp = _power(u, h_p, vbase_v * per_mag)
    hq = _power(u, h_q, vbase_v * per_mag)
    if switches:
        if u <= vlow:
            hp = hq = u
        elif u <= vmin:
            hp = hq = vlow + (at_vmin - vlow) / (vmin - vlow if vmin > vlow else 1.0) * (u - vlow)
        elif u > vmax:
            hp = hq = u / above_div
    a, b = p_w * hp * per_base, -q_var * hq * per_base
    return complex(a * re - b * im, a * im + b * re)


@njit(cache=True, error_model="numpy")
def drawn_row(
    v: np.ndarray,
    p_w: np.ndarray,
    q_var: np.ndarray,
    vbase_v: float,
    h_p: float,
    h_q: float,
    switches: bool,
    vmin: float,
    vmax: float,
    vlow: float,
    at_vmin: float,
    above_div: float,
    out: np.ndarray,
) -> None:
    """out (S,) ← `drawn` of one branch at its voltages v (S,) and powers p_w, q_var (S,).
    A constant-power branch (both exponents −1) draws (P − jQ)·V/|V|² in band and, when
    it switches, (P − jQ)·V/(V_base²·above_div) above vmaxpu — `drawn` there, in one pass
    without branches that the compiler vectorizes; `drawn` itself below vminpu and for
    every other law."""
    constant_power = h_p == -1.0 and h_q == -1.0
    if constant_power:
        low, high = (vmin * vbase_v) ** 2, (vmax * vbase_v) ** 2 if switches else np.inf  # the band in |V|²
        per_above = 1.0 / (vbase_v * vbase_v * above_div)
        below = 0
        for s in range(v.size):
            re, im = v[s].real, v[s].imag
            mag2 = re * re + im * im
            inverse = 1.0 / mag2
            per = per_above if mag2 > high else inverse
            out[s] = complex((p_w[s] * re + q_var[s] * im) * per, (p_w[s] * im - q_var[s] * re) * per)
            below += mag2 <= low
        if not (switches and below):
            return
    for s in range(v.size):
        if constant_power and not v[s].real * v[s].real + v[s].imag * v[s].imag <= low:
            continue
        out[s] = drawn(v[s], p_w[s], q_var[s], vbase_v, h_p, h_q, switches, vmin, vmax, vlow, at_vmin, above_div)


@njit(cache=True, error_model="numpy")
def _power(u: float, exponent: float, per_u: float) -> float:
    """u**exponent (per_u = 1/u); the exponents of constant power, current and impedance
    (−1, 0, 1) as 1/u, one or u."""
    if exponent == -1.0:
        return per_u
    if exponent == 0.0:
        return 1.0
    if exponent == 1.0:
        return u
    return u**exponent


@njit(cache=True, error_model="numpy")
def branch_currents(v_k: np.ndarray, loads: tuple, ders: tuple, y: tuple, out: np.ndarray) -> None:
    """out (m, S) ← Y·v_k (CSR `y`: indptr, indices, data; none when indptr is all zero)
    plus the currents the load branches draw (`drawn_row`, taken out of node a and
    into node b) and the DER branches inject (I = conj(S/V)), at the voltages v_k (m, S)
    of K; branch ends are positions in K, m meaning ground."""
    m, n = v_k.shape
    indptr, indices, data = y
    for r in range(m):
        for s in range(n):
            out[r, s] = 0.0
        for t in range(indptr[r], indptr[r + 1]):
            for s in range(n):
                out[r, s] += data[t] * v_k[indices[t], s]
    a_load, b_load, p, q, vbase, h_p, h_q, switches, vmin, vmax, vlow, at_vmin, above_div = loads
    across = np.empty(n, dtype=np.complex128)
    current = np.empty(n, dtype=np.complex128)
    for i in range(a_load.size):
        a, b = a_load[i], b_load[i]
        for s in range(n):
            across[s] = v_k[a, s] - v_k[b, s] if b < m else v_k[a, s]
        drawn_row(
            across,
            p[i],
            q[i],
            vbase[i],
            h_p[i],
            h_q[i],
            switches[i],
            vmin[i],
            vmax[i],
            vlow[i],
            at_vmin[i],
            above_div[i],
            current,
        )
        for s in range(n):
            out[a, s] -= current[s]
        if b < m:
            for s in range(n):
                out[b, s] += current[s]
    a_der, b_der, s_der = ders
    for i in range(a_der.size):
        a, b = a_der[i], b_der[i]
        for s in range(n):
            across[s] = v_k[a, s] - v_k[b, s] if b < m else v_k[a, s]
        for s in range(n):
            re, im = across[s].real, across[s].imag
            sr, si = s_der[i, s].real, s_der[i, s].imag
            per_mag2 = 1.0 / (re * re + im * im)
            current[s] = complex((sr * re + si * im) * per_mag2, (sr * im - si * re) * per_mag2)  # conj(S/V)
        for s in range(n):
            out[a, s] += current[s]
        if b < m:
            for s in range(n):
                out[b, s] -= current[s]
