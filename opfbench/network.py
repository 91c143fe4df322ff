"""The one network model shared by power flow, the local rules and the OPF formulations.

Storage follows MATPOWER: loads in MW/MVAr, branch impedances in p.u. on `base_mva` and
the bus's base kV. Buses keep their external numbers (`bus_ids`); every array indexed by
bus uses the *internal* position 0..n-1. Sign convention: injections positive into the
grid, loads positive when consuming.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp

from opfbench.errors import NetworkError

DerKind = Literal["PV", "DFIG"]

_BUS_ARRAYS = ("bus_ids", "bus_type", "base_kv", "load_p_mw", "load_q_mvar", "gs_mw", "bs_mvar", "vmin", "vmax")
_BRANCH_ARRAYS = ("f", "t", "r", "x", "b", "tap", "shift", "status")
_GEN_ARRAYS = ("gen_bus", "gen_p_mw", "gen_q_mvar", "gen_vset")
_DTYPES = {"bus_ids": int, "bus_type": int, "f": int, "t": int, "status": bool, "gen_bus": int}


@dataclass(frozen=True)
class DER:
    """A DER unit: `bus` is the internal bus index, `rating_mw` its rated active power P̄
    (MW), `s_mva` its nameplate apparent power S̄ (MVA; None = P̄, as for the paper's PV
    and DFIG units)."""

    bus: int
    kind: DerKind
    rating_mw: float
    s_mva: float | None = None

    @property
    def s_rated_mva(self) -> float:
        """Nameplate apparent power S̄ (MVA)."""
        return self.rating_mw if self.s_mva is None else self.s_mva


@dataclass(frozen=True, eq=False)
class Network:
    """Buses, branches (π model), loads, fixed generators, DER units and one slack bus.

    Arrays (length n_bus): bus_ids, base_kv, load_p_mw, load_q_mvar, gs_mw, bs_mvar,
    vmin, vmax, bus_type (1 PQ, 2 PV, 3 slack). Arrays (length n_branch): f, t (internal
    bus indices), r, x, b (p.u.), tap (ratio, 1.0 = none), shift (degrees), status (bool).
    Fixed generators (other than the slack's) are kept as gen_bus/gen_p_mw/gen_q_mvar/
    gen_vset: at PV buses the solver holds |V| = gen_vset, elsewhere they are P/Q
    injections.

    The network is immutable: the constructor copies every array and makes the copies
    read-only, so a shared (cached) network cannot be changed by one caller for all
    others. It checks array lengths, finite values, non-negative branch resistance and
    vmin ≤ vmax per bus, and that every bus is connected to the slack.
    """

    name: str
    base_mva: float
    bus_ids: np.ndarray
    bus_type: np.ndarray
    base_kv: np.ndarray
    load_p_mw: np.ndarray
    load_q_mvar: np.ndarray
    gs_mw: np.ndarray
    bs_mvar: np.ndarray
    vmin: np.ndarray
    vmax: np.ndarray
    f: np.ndarray
    t: np.ndarray
    r: np.ndarray
    x: np.ndarray
    b: np.ndarray
    tap: np.ndarray
    shift: np.ndarray
    status: np.ndarray
    slack: int
    v_slack: float = 1.0
    gen_bus: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    gen_p_mw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gen_q_mvar: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gen_vset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ders: tuple[DER, ...] = ()

    def __post_init__(self) -> None:
        for name in _BUS_ARRAYS + _BRANCH_ARRAYS + _GEN_ARRAYS:
            arr: np.ndarray = np.array(getattr(self, name), dtype=_DTYPES.get(name, float))
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        self._check_arrays()
        self._check_connected()

    def _check_arrays(self) -> None:
        for group, n in ((_BUS_ARRAYS, self.n_bus), (_BRANCH_ARRAYS, self.n_branch), (_GEN_ARRAYS, len(self.gen_bus))):
            for name in group:
                arr = getattr(self, name)
                if arr.shape != (n,):
                    raise NetworkError(f"{self.name}: {name} has shape {arr.shape}, expected ({n},) like {group[0]}")
                if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                    raise NetworkError(
                        f"{self.name}: {name} has a non-finite value at position {int(np.argmin(np.isfinite(arr)))}"
                    )
        if not (np.isfinite(self.base_mva) and self.base_mva > 0):
            raise NetworkError(f"{self.name}: base_mva must be a finite positive number, got {self.base_mva}")
        for name in ("f", "t", "gen_bus"):
            arr = getattr(self, name)
            if arr.size and (arr.min() < 0 or arr.max() >= self.n_bus):
                raise NetworkError(f"{self.name}: {name} refers to a bus index outside 0..{self.n_bus - 1}")
        if not 0 <= self.slack < self.n_bus:
            raise NetworkError(f"{self.name}: slack index {self.slack} outside 0..{self.n_bus - 1}")
        neg_r = np.flatnonzero(self.r < 0)
        if neg_r.size:
            k = neg_r[0]
            raise NetworkError(
                f"{self.name}: branch {k + 1} ({self.bus_ids[self.f[k]]}-{self.bus_ids[self.t[k]]}) has negative "
                f"resistance r = {self.r[k]:.6g} p.u.; negative r makes negative losses and is refused"
            )
        crossed = np.flatnonzero(self.vmin > self.vmax)
        if crossed.size:
            i = crossed[0]
            raise NetworkError(f"{self.name}: bus {self.bus_ids[i]} has Vmin {self.vmin[i]:g} > Vmax {self.vmax[i]:g} p.u.")
        for d in self.ders:
            if d.kind not in ("PV", "DFIG"):
                raise NetworkError(f"{self.name}: unknown DER kind {d.kind!r}; expected PV or DFIG")
            if not 0 <= d.bus < self.n_bus:
                raise NetworkError(f"{self.name}: DER at bus index {d.bus} outside 0..{self.n_bus - 1}")
            if not (np.isfinite(d.rating_mw) and d.rating_mw > 0):
                raise NetworkError(f"{self.name}: DER at bus {self.bus_ids[d.bus]} has rating {d.rating_mw} MW; must be > 0")
            if not (np.isfinite(d.s_rated_mva) and d.s_rated_mva >= d.rating_mw):
                raise NetworkError(
                    f"{self.name}: DER at bus {self.bus_ids[d.bus]} has S̄ {d.s_rated_mva} MVA; must be finite and ≥ "
                    f"its rated P {d.rating_mw} MW"
                )

    # ----- sizes and lookups -------------------------------------------------------
    @property
    def n_bus(self) -> int:
        return len(self.bus_ids)

    @property
    def n_branch(self) -> int:
        return len(self.f)

    def index_of(self, bus_id: int) -> int:
        """Internal index of the bus with external number `bus_id`."""
        hits = np.flatnonzero(self.bus_ids == bus_id)
        if hits.size == 0:
            raise NetworkError(f"{self.name}: no bus numbered {bus_id}")
        return int(hits[0])

    @property
    def der_bus(self) -> np.ndarray:
        return np.array([d.bus for d in self.ders], dtype=int)

    @property
    def der_rating_mw(self) -> np.ndarray:
        return np.array([d.rating_mw for d in self.ders], dtype=float)

    @property
    def der_s_mva(self) -> np.ndarray:
        """Nameplate apparent power S̄ of each DER (MVA)."""
        return np.array([d.s_rated_mva for d in self.ders], dtype=float)

    @property
    def der_kinds(self) -> tuple[DerKind, ...]:
        return tuple(d.kind for d in self.ders)

    @property
    def pv_buses(self) -> np.ndarray:
        """Internal indices of voltage-controlled (PV) buses, excluding the slack."""
        return np.flatnonzero(self.bus_type == 2)

    def with_changes(self, **changes) -> "Network":
        """A copy with some fields replaced (the network itself is immutable)."""
        return replace(self, **changes)

    # ----- electrical matrices -----------------------------------------------------
    @cached_property
    def ybus_sparse(self) -> sp.csr_matrix:
        """Sparse (CSR) complex bus admittance matrix (p.u.), MATPOWER's makeYbus
        conventions; every diagonal entry is stored, even when zero."""
        yff, yft, ytf, ytt = self.branch_admittances
        n = self.n_bus
        diag = np.arange(n)
        rows = np.concatenate([self.f, self.f, self.t, self.t, diag])
        cols = np.concatenate([self.f, self.t, self.f, self.t, diag])
        vals = np.concatenate([yff, yft, ytf, ytt, (self.gs_mw + 1j * self.bs_mvar) / self.base_mva])
        y = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))  # duplicates are summed
        y.sort_indices()
        return y

    @cached_property
    def ybus(self) -> np.ndarray:
        """Dense complex bus admittance matrix (p.u.), read-only; n_bus² entries, so only
        for small feeders — large ones use `ybus_sparse`."""
        y = self.ybus_sparse.toarray()
        y.setflags(write=False)
        return y

    @cached_property
    def branch_admittances(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-branch π-model admittances (yff, yft, ytf, ytt); zero for open branches."""
        on = self.status.astype(float)
        ys = on / (self.r + 1j * self.x)
        bc = on * self.b
        tap = self.tap * np.exp(1j * np.deg2rad(self.shift))
        ytt = ys + 1j * bc / 2
        yff = ytt / (tap * np.conj(tap))
        yft = -ys / np.conj(tap)
        ytf = -ys / tap
        return yff, yft, ytf, ytt

    # ----- topology ----------------------------------------------------------------
    @cached_property
    def meshed(self) -> bool:
        """True when the in-service branches contain a loop."""
        return int(self.status.sum()) > self.n_bus - 1

    @cached_property
    def _bfs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Breadth-first search from the slack over in-service branches.

        Returns (order, parent, parent_branch): visiting order, parent bus index (-1 for the
        slack) and the branch connecting each bus to its parent (-1 for the slack).
        """
        n = self.n_bus
        adjacency: list[list[tuple[int, int]]] = [[] for _ in range(n)]
        for branch in np.flatnonzero(self.status).tolist():
            adjacency[self.f[branch]].append((int(self.t[branch]), branch))
            adjacency[self.t[branch]].append((int(self.f[branch]), branch))
        parent = np.full(n, -1)
        parent_branch = np.full(n, -1)
        seen = np.zeros(n, dtype=bool)
        seen[self.slack] = True
        order = []
        queue = deque([self.slack])
        while queue:
            i = queue.popleft()
            order.append(i)
            for j, k in adjacency[i]:
                if not seen[j]:
                    seen[j] = True
                    parent[j] = i
                    parent_branch[j] = k
                    queue.append(j)
        return np.array(order), parent, parent_branch

    def _check_connected(self) -> None:
        order = self._bfs[0]
        if len(order) < self.n_bus:
            missing = np.setdiff1d(np.arange(self.n_bus), order)
            ids = ", ".join(str(i) for i in self.bus_ids[missing][:20])
            raise NetworkError(
                f"{self.name}: {len(missing)} bus(es) islanded from the slack bus "
                f"{self.bus_ids[self.slack]} by the in-service branches: {ids}"
            )

    @property
    def parent(self) -> np.ndarray:
        """Parent bus (internal index) of each bus on the BFS tree from the slack; -1 at the slack.
        On a radial feeder this is the unique upstream bus."""
        return self._bfs[1]

    @property
    def parent_branch(self) -> np.ndarray:
        """Branch from each bus to its parent (-1 at the slack)."""
        return self._bfs[2]

    @property
    def bfs_order(self) -> np.ndarray:
        """Buses in breadth-first order from the slack (parents before children)."""
        return self._bfs[0]

    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        """Children of each bus on the BFS tree."""
        kids: list[list[int]] = [[] for _ in range(self.n_bus)]
        for j, p in enumerate(self.parent):
            if p >= 0:
                kids[p].append(j)
        return tuple(tuple(k) for k in kids)

    @cached_property
    def incident_branches(self) -> tuple[tuple[int, ...], ...]:
        """In-service branches touching each bus (what a local flow meter could see)."""
        inc: list[list[int]] = [[] for _ in range(self.n_bus)]
        for k in np.flatnonzero(self.status):
            inc[self.f[k]].append(int(k))
            inc[self.t[k]].append(int(k))
        return tuple(tuple(i) for i in inc)

    @property
    def is_leaf(self) -> np.ndarray:
        """Bool per bus: a leaf has exactly one in-service incident branch (and is not the slack)."""
        degree = np.array([len(i) for i in self.incident_branches])
        leaf = degree == 1
        leaf[self.slack] = False
        return leaf

    def summary(self) -> dict:
        return {
            "case": self.name,
            "buses": self.n_bus,
            "branches": int(self.status.sum()),
            "branches_open": int((~self.status).sum()),
            "ders": len(self.ders),
            "meshed": self.meshed,
            "load_mw": float(self.load_p_mw.sum()),
            "load_mvar": float(self.load_q_mvar.sum()),
            "base_mva": self.base_mva,
        }
