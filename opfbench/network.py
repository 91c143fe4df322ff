"""The one network model shared by power flow, the local rules and the OPF formulations.

Storage follows MATPOWER: loads in MW/MVAr, branch impedances in p.u. on `base_mva` and
the bus's base kV. Buses keep their external numbers (`bus_ids`); every array indexed by
bus uses the *internal* position 0..n-1. Sign convention: injections positive into the
grid, loads positive when consuming.

Loads are elements: `load_bus` names the bus of each (several may share a bus); the bus
arrays `load_p_mw`/`load_q_mvar` are the nominal (stored) totals per bus. A scenario gives
either one scale on those totals or every element's own P and Q (`opfbench.scenario`).

DER kinds (`DER.kind`, capability in `opfbench.capability`): "PV" and "DFIG" are the
paper's units; "inverter" is a generic inverter-coupled unit (PV, wind, biomass, hydro
static generators of real grids) with a nameplate S̄ and the VDE-AR-N 4105 power-factor
range. `DER.energy` is its primary energy: the night modes act on the solar units.

Every DER has a unique, stable name (`Network.der_names`): the source's element name where
it has one (`DER.name`), else derived from its kind and bus number (`PV-18`,
`inverter-24`, `inverter-24-2` for a second one of that kind at that bus). Several DER may
share a bus: what a DER measures of its bus's load is its share of it, in proportion to
the units' nameplate ratings S̄ (`Network.der_share`), so that the units at one bus
together compensate the bus's load once.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp

from opfbench.errors import NetworkError

DerKind = Literal["PV", "DFIG", "inverter"]
DER_KINDS: tuple[str, ...] = ("PV", "DFIG", "inverter")
DerEnergy = Literal["solar", "wind", "biomass", "hydro", "other"]
DER_ENERGIES: tuple[str, ...] = ("solar", "wind", "biomass", "hydro", "other")
_KIND_ENERGY = {"PV": "solar", "DFIG": "wind", "inverter": "solar"}

_BUS_ARRAYS = ("bus_ids", "bus_type", "base_kv", "load_p_mw", "load_q_mvar", "gs_mw", "bs_mvar", "vmin", "vmax")
_BRANCH_ARRAYS = ("f", "t", "r", "x", "b", "g", "tap", "shift", "status")
_GEN_ARRAYS = ("gen_bus", "gen_p_mw", "gen_q_mvar", "gen_vset")
_DTYPES = {"bus_ids": int, "bus_type": int, "f": int, "t": int, "status": bool, "gen_bus": int, "load_bus": int}
BUS_TYPES = {1: "PQ", 2: "PV", 3: "slack"}  # MATPOWER's codes; its 4 (isolated) is not a bus of the network
V_SETPOINT_PU = (0.5, 1.5)
"""Voltage magnitudes a slack or a voltage-controlled generator may be held at (p.u.);
outside, the value is a typo (a sign, kV for p.u.), never a distribution feeder."""
V_LIMIT_MAX_PU = 2.0
"""The largest voltage limit (p.u.) accepted; vmin lies in [0, vmax], vmax in
[V_SETPOINT_PU[0], V_LIMIT_MAX_PU] (a band below 0.5 p.u. is no feeder's)."""
BASE_MVA_RANGE = (1e-3, 1e6)
"""Power bases (MVA) accepted: 1 kVA to 1 TVA; beyond, per-unit arithmetic over- or underflows."""


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class DER:
    """A DER unit: `bus` is the internal bus index, `rating_mw` its rated active power P̄
    (MW), `s_mva` its nameplate apparent power S̄ (MVA; None = P̄, as for the paper's PV
    and DFIG units), `energy` its primary energy (None = the kind's: PV solar, DFIG wind,
    inverter solar), `name` the source's element name (None: derived from kind and bus,
    `Network.der_names`)."""

    bus: int
    kind: DerKind
    rating_mw: float
    s_mva: float | None = None
    energy: DerEnergy | None = None
    name: str | None = None

    @property
    def s_rated_mva(self) -> float:
        """Nameplate apparent power S̄ (MVA)."""
        return self.rating_mw if self.s_mva is None else self.s_mva

    @property
    def primary_energy(self) -> str:
        """Primary energy: `energy`, or the kind's when not given."""
        return _KIND_ENERGY.get(self.kind, "other") if self.energy is None else self.energy


class DerFleet:
    """The per-DER arrays every network derives from its `ders` (balanced and three-phase
    alike: `Network`, `multiphase.PhaseNetwork`)."""

    ders: tuple[DER, ...]

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
    def der_solar(self) -> np.ndarray:
        """Bool per DER: a solar unit (what the night modes switch off or give "Q at night")."""
        return np.array([d.primary_energy == "solar" for d in self.ders], dtype=bool)


@dataclass(frozen=True, eq=False)
class Network(DerFleet):
    """Buses, branches (π model), loads, fixed generators, DER units and one slack bus.

    Arrays (length n_bus): bus_ids, base_kv, load_p_mw, load_q_mvar, gs_mw, bs_mvar,
    vmin, vmax, bus_type (1 PQ, 2 PV, 3 slack). Arrays (length n_branch): f, t (internal
    bus indices), r, x, b (p.u.), g (p.u.: the π model's shunt conductance, g/2 at each
    end like b — pandapower's BR_G, e.g. a transformer's iron losses; empty = none), tap
    (ratio, 1.0 = none), shift (degrees), status (bool). `load_bus` (n_load,): the bus of
    each load element (empty = one element per bus with a nonzero nominal load, the
    MATPOWER convention).
    Fixed generators (other than the slack's) are kept as gen_bus/gen_p_mw/gen_q_mvar/
    gen_vset: at PV buses the solver holds |V| = gen_vset, elsewhere they are P/Q
    injections.

    The network is immutable: the constructor copies every array and makes the copies
    read-only, and every array it derives (Y-bus — the sparse matrix's data, indices and
    indptr too —, branch admittances, the BFS tree) is read-only as well, so a shared
    (cached) network cannot be changed by one caller for all others. It checks array
    lengths, finite values, base_mva within BASE_MVA_RANGE, unique bus numbers, bus
    types (one slack, of type 3, at `slack`), non-negative branch resistance, in-service
    branches joining two buses through a non-zero impedance, positive taps, phase shifts
    within ±360°, finite branch admittances, voltage limits, base kV and setpoints
    (`_check_voltages`), and that every bus is connected to the slack.
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
    g: np.ndarray = field(default_factory=lambda: np.zeros(0))
    load_bus: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def __post_init__(self) -> None:
        if np.size(self.g) == 0:
            object.__setattr__(self, "g", np.zeros(np.size(self.f)))
        if np.size(self.load_bus) == 0 and np.shape(self.load_p_mw) == np.shape(self.load_q_mvar):
            nominal = (np.asarray(self.load_p_mw) != 0) | (np.asarray(self.load_q_mvar) != 0)
            object.__setattr__(self, "load_bus", np.flatnonzero(nominal))  # else the shape check names the field
        for name in _BUS_ARRAYS + _BRANCH_ARRAYS + _GEN_ARRAYS + ("load_bus",):
            object.__setattr__(self, name, _frozen(_array(self.name, name, getattr(self, name))))
        for name in ("base_mva", "v_slack"):
            object.__setattr__(self, name, _number(self.name, name, getattr(self, name)))
        if not isinstance(self.name, str):
            raise NetworkError(f"a network's name must be text, got {self.name!r}")
        if isinstance(self.slack, bool) or not isinstance(self.slack, (int, np.integer)):
            raise NetworkError(f"{self.name}: slack must be a bus index (an integer), got {self.slack!r}")
        object.__setattr__(self, "slack", int(self.slack))
        object.__setattr__(self, "ders", _der_tuple(self.name, self.ders))
        self._check_arrays()
        self._check_buses()
        self._check_voltages()
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
        if not BASE_MVA_RANGE[0] <= self.base_mva <= BASE_MVA_RANGE[1]:
            raise NetworkError(
                f"{self.name}: base_mva {self.base_mva:g} MVA outside [{BASE_MVA_RANGE[0]:g}, {BASE_MVA_RANGE[1]:g}] MVA"
            )
        if self.load_bus.ndim != 1:
            raise NetworkError(f"{self.name}: load_bus must be 1-D, got shape {self.load_bus.shape}")
        for name in ("f", "t", "gen_bus", "load_bus"):
            arr = getattr(self, name)
            if arr.size and (arr.min() < 0 or arr.max() >= self.n_bus):
                raise NetworkError(f"{self.name}: {name} refers to a bus index outside 0..{self.n_bus - 1}")
        if not 0 <= self.slack < self.n_bus:
            raise NetworkError(f"{self.name}: slack index {self.slack} outside 0..{self.n_bus - 1}")
        self._check_branches()
        neg_r = np.flatnonzero(self.r < 0)
        if neg_r.size:
            k = neg_r[0]
            raise NetworkError(
                f"{self.name}: branch {k + 1} ({self.bus_ids[self.f[k]]}-{self.bus_ids[self.t[k]]}) has negative "
                f"resistance r = {self.r[k]:.6g} p.u.; negative r makes negative losses and is refused"
            )
        repeated = sorted(n for n, c in Counter(d.name for d in self.ders if d.name is not None).items() if c > 1)
        if repeated:
            raise NetworkError(f"{self.name}: DER name {repeated[0]!r} is given to more than one DER; a DER's name is unique")
        for d in self.ders:
            if d.kind not in DER_KINDS:
                raise NetworkError(f"{self.name}: unknown DER kind {d.kind!r}; expected one of {', '.join(DER_KINDS)}")
            if d.primary_energy not in DER_ENERGIES:
                raise NetworkError(f"{self.name}: unknown DER energy {d.energy!r}; expected one of {', '.join(DER_ENERGIES)}")
            if not 0 <= d.bus < self.n_bus:
                raise NetworkError(f"{self.name}: DER at bus index {d.bus} outside 0..{self.n_bus - 1}")
            if not (np.isfinite(d.rating_mw) and d.rating_mw > 0):
                raise NetworkError(f"{self.name}: DER at bus {self.bus_ids[d.bus]} has rating {d.rating_mw} MW; must be > 0")
            if not (np.isfinite(d.s_rated_mva) and d.s_rated_mva >= d.rating_mw):
                raise NetworkError(
                    f"{self.name}: DER at bus {self.bus_ids[d.bus]} has S̄ {d.s_rated_mva} MVA; must be finite and ≥ "
                    f"its rated P {d.rating_mw} MW"
                )

    def _check_branches(self) -> None:
        """In-service branches join two buses through a non-zero impedance; taps > 0, phase
        shifts within ±360°, and the π-model admittances they give finite."""

        def refuse(k: int, problem: str) -> None:
            raise NetworkError(f"{self.name}: branch {k + 1} ({self.bus_ids[self.f[k]]}-{self.bus_ids[self.t[k]]}) {problem}")

        on = self.status
        for rows, problem in (
            (on & (self.f == self.t), "connects a bus to itself"),
            (on & (self.r == 0) & (self.x == 0), "is in service with zero impedance (r = x = 0)"),
            (self.tap <= 0, "has tap ratio {tap:g}; it must be > 0 (1 = no transformer)"),
            (np.abs(self.shift) > 360, "has phase shift {shift:g}°; it must lie within ±360°"),
        ):
            bad = np.flatnonzero(rows)
            if bad.size:
                refuse(int(bad[0]), problem.format(tap=self.tap[bad[0]], shift=self.shift[bad[0]]))
        with np.errstate(all="ignore"):
            finite = np.logical_and.reduce([np.isfinite(y) for y in self.branch_admittances])
        if not finite.all():
            k = int(np.flatnonzero(~finite)[0])
            refuse(k, f"has an admittance that is not a finite number (r {self.r[k]:g}, x {self.x[k]:g}, tap {self.tap[k]:g})")

    def _check_buses(self) -> None:
        """Unique bus numbers; bus types 1/2/3 with exactly one slack (type 3), at `slack`."""
        ids, first = np.unique(self.bus_ids, return_index=True)
        if ids.size < self.n_bus:
            dup = self.bus_ids[np.setdiff1d(np.arange(self.n_bus), first)[0]]
            raise NetworkError(f"{self.name}: bus number {dup} is used by more than one bus")
        unknown = np.flatnonzero(~np.isin(self.bus_type, list(BUS_TYPES)))
        if unknown.size:
            i = unknown[0]
            raise NetworkError(
                f"{self.name}: bus {self.bus_ids[i]} has type {self.bus_type[i]}; expected "
                + ", ".join(f"{code} ({kind})" for code, kind in BUS_TYPES.items())
            )
        slacks = np.flatnonzero(self.bus_type == 3)
        if slacks.tolist() != [self.slack]:
            marked = ", ".join(str(b) for b in self.bus_ids[slacks]) or "none"
            raise NetworkError(
                f"{self.name}: slack is bus {self.bus_ids[self.slack]} (index {self.slack}) but bus_type marks "
                f"{marked} as the slack (type 3); exactly the slack bus must have type 3"
            )

    def _check_voltages(self) -> None:
        """0 ≤ vmin ≤ vmax per bus, vmax within [V_SETPOINT_PU[0], V_LIMIT_MAX_PU]; the
        slack's and PV generators' setpoints within V_SETPOINT_PU; base kV ≥ 0."""
        lo, hi = V_SETPOINT_PU
        bad = np.flatnonzero((self.vmin < 0) | (self.vmin > self.vmax) | (self.vmax > V_LIMIT_MAX_PU) | (self.vmax < lo))
        if bad.size:
            i = bad[0]
            raise NetworkError(
                f"{self.name}: bus {self.bus_ids[i]} has voltage limits Vmin {self.vmin[i]:g}, Vmax {self.vmax[i]:g} p.u.; "
                f"they must satisfy 0 ≤ Vmin ≤ Vmax and {lo:g} ≤ Vmax ≤ {V_LIMIT_MAX_PU:g}"
                + (f" ({bad.size} such buses)" if bad.size > 1 else "")
            )
        negative_kv = np.flatnonzero(self.base_kv < 0)
        if negative_kv.size:
            i = negative_kv[0]
            raise NetworkError(f"{self.name}: bus {self.bus_ids[i]} has base voltage {self.base_kv[i]:g} kV; it must be ≥ 0")
        if not lo <= self.v_slack <= hi:
            raise NetworkError(
                f"{self.name}: slack voltage {self.v_slack:g} p.u. (bus {self.bus_ids[self.slack]}) outside [{lo:g}, {hi:g}] p.u."
            )
        held = np.isin(self.gen_bus, self.pv_buses)
        bad = np.flatnonzero(held & ~((self.gen_vset >= lo) & (self.gen_vset <= hi)))
        if bad.size:
            g = bad[0]
            raise NetworkError(
                f"{self.name}: generator at PV bus {self.bus_ids[self.gen_bus[g]]} holds |V| = {self.gen_vset[g]:g} p.u., "
                f"outside [{lo:g}, {hi:g}] p.u."
            )

    # ----- sizes and lookups -------------------------------------------------------
    @property
    def n_bus(self) -> int:
        return len(self.bus_ids)

    @property
    def n_branch(self) -> int:
        return len(self.f)

    def index_of(self, bus_id: int) -> int:
        """Internal index of the bus with external number `bus_id` (an integer)."""
        if isinstance(bus_id, (bool, np.bool_)) or not isinstance(bus_id, (int, np.integer)):
            raise NetworkError(f"{self.name}: a bus number is an integer, got {bus_id!r}")
        hits = np.flatnonzero(self.bus_ids == bus_id)
        if hits.size == 0:
            raise NetworkError(f"{self.name}: no bus numbered {bus_id}")
        return int(hits[0])

    @cached_property
    def der_names(self) -> tuple[str, ...]:
        """Each DER's unique name: `DER.name` where the source gives one, else
        `KIND-BUS` (external bus number), with `-2`, `-3`, … for a further unit that would
        take a name already used."""
        used = {d.name for d in self.ders if d.name is not None}
        out = []
        for d in self.ders:
            if d.name is not None:
                out.append(d.name)
                continue
            base = f"{d.kind}-{int(self.bus_ids[d.bus])}"
            name, n = base, 1
            while name in used:
                n += 1
                name = f"{base}-{n}"
            used.add(name)
            out.append(name)
        return tuple(out)

    @cached_property
    def der_share(self) -> np.ndarray:
        """(n_der,) each DER's share of what it measures of its bus (the bus's load, the
        flows its rule compensates): S̄ / Σ S̄ of the DER at that bus — 1 for a DER alone
        at its bus, so the units at one bus together compensate its load once."""
        s = self.der_s_mva
        total = np.zeros(self.n_bus)
        np.add.at(total, self.der_bus, s)
        return _frozen(s / total[self.der_bus])

    @property
    def n_load(self) -> int:
        return len(self.load_bus)

    @cached_property
    def load_incidence(self) -> sp.csr_matrix:
        """(n_bus, n_load) 0/1 matrix summing load elements onto their buses."""
        n = self.n_load
        return sp.csr_matrix((np.ones(n), (self.load_bus, np.arange(n))), shape=(self.n_bus, n))

    @property
    def pv_buses(self) -> np.ndarray:
        """Internal indices of voltage-controlled (PV) buses, excluding the slack."""
        return np.flatnonzero(self.bus_type == 2)

    def with_changes(self, **changes) -> "Network":
        """A copy with some fields replaced (the network itself is immutable), checked
        like a new network. A new branch count without `g` keeps a conductance-free network
        conductance-free (and refuses to guess a nonzero one); replacing the loads without
        `load_bus` re-derives the load elements of a network that had the default ones."""
        unknown = sorted(set(changes) - {f.name for f in fields(self)})
        if unknown:
            raise NetworkError(f"{self.name}: a network has no field {', '.join(unknown)}")
        if "g" not in changes and np.size(changes.get("f", self.f)) != self.n_branch:
            if self.g.any():
                raise NetworkError(f"{self.name}: the branches change but g (branch shunt conductance) is not given")
            changes["g"] = np.zeros(0)
        if "load_bus" not in changes and any(k in changes for k in ("load_p_mw", "load_q_mvar", "bus_ids")):
            nominal = np.flatnonzero((self.load_p_mw != 0) | (self.load_q_mvar != 0))
            if np.array_equal(self.load_bus, nominal):
                changes["load_bus"] = np.zeros(0, dtype=int)
        return replace(self, **changes)

    # ----- electrical matrices -----------------------------------------------------
    @cached_property
    def _ybus_csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The Y-bus's CSR arrays (data, indices, indptr), read-only: canonical (sorted
        indices, duplicates summed), every diagonal entry stored."""
        yff, yft, ytf, ytt = self.branch_admittances
        n = self.n_bus
        diag = np.arange(n)
        rows = np.concatenate([self.f, self.f, self.t, self.t, diag])
        cols = np.concatenate([self.f, self.t, self.f, self.t, diag])
        vals = np.concatenate([yff, yft, ytf, ytt, (self.gs_mw + 1j * self.bs_mvar) / self.base_mva])
        y = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))  # duplicates are summed
        y.sort_indices()
        return _frozen(y.data), _frozen(y.indices), _frozen(y.indptr)

    @property
    def ybus_sparse(self) -> sp.csr_matrix:
        """Sparse (CSR) complex bus admittance matrix (p.u.), MATPOWER's makeYbus
        conventions; every diagonal entry is stored, even when zero. Each call returns a
        new matrix over the network's read-only arrays: a value cannot be written, and a
        change of structure (a new entry) stays in the caller's matrix."""
        y = sp.csr_matrix(self._ybus_csr, shape=(self.n_bus, self.n_bus), copy=False)
        y.has_canonical_format = True
        return y

    @cached_property
    def ybus(self) -> np.ndarray:
        """Dense complex bus admittance matrix (p.u.), read-only; n_bus² entries, so only
        for small feeders — large ones use `ybus_sparse`."""
        return _frozen(self.ybus_sparse.toarray())

    @cached_property
    def branch_admittances(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-branch π-model admittances (yff, yft, ytf, ytt); zero for open branches."""
        on = self.status.astype(float)
        ys = on / (self.r + 1j * self.x)
        bc = on * self.b
        tap = self.tap * np.exp(1j * np.deg2rad(self.shift))
        ytt = ys + 1j * bc / 2 if not self.g.any() else ys + (on * self.g + 1j * bc) / 2
        yff = ytt / (tap * np.conj(tap))
        yft = -ys / np.conj(tap)
        ytf = -ys / tap
        return _frozen(yff), _frozen(yft), _frozen(ytf), _frozen(ytt)

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
        order: list[int] = []
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
        return _frozen(np.array(order)), _frozen(parent), _frozen(parent_branch)

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
            "loads": self.n_load,
            "meshed": self.meshed,
            "load_mw": float(self.load_p_mw.sum()),
            "load_mvar": float(self.load_q_mvar.sum()),
            "base_mva": self.base_mva,
        }


def _array(network: str, name: str, value: object) -> np.ndarray:
    """`value` as a copy of the field's dtype; NetworkError naming the field for what is
    not numeric (text, complex, None, ragged rows) or an integer field given fractions."""
    kind = _DTYPES.get(name, float)
    try:
        raw = np.array(value)
    except ValueError:
        raise NetworkError(f"{network}: {name} is not a regular array (rows of different lengths)") from None
    if raw.dtype.kind not in "biuf":
        raise NetworkError(f"{network}: {name} must be real numbers, got {raw.dtype} values")
    if kind is bool:
        if raw.size and not np.all(np.isin(raw, (0, 1))):
            raise NetworkError(f"{network}: {name} must be true/false (1/0)")
        return raw.astype(bool)
    if kind is int and raw.dtype.kind == "f":
        whole = np.isfinite(raw) & (raw == np.round(raw)) & (np.abs(raw) < 2.0**53)
        if not np.all(whole):
            bad = raw.reshape(-1)[np.flatnonzero(~whole.reshape(-1))[0]]
            raise NetworkError(f"{network}: {name} must be whole numbers, got {bad:g}")
    if kind is int and raw.dtype.kind == "u" and raw.size and raw.max() > np.iinfo(np.int64).max:
        raise NetworkError(f"{network}: {name} value {raw.max()} does not fit a 64-bit integer")
    return raw.astype(kind)


def _der_tuple(network: str, ders: object) -> tuple[DER, ...]:
    """`ders` as a tuple of DER units whose bus is an index (an integer) and whose ratings
    are real numbers; NetworkError naming the unit otherwise."""
    try:
        units: tuple[object, ...] = tuple(ders)  # type: ignore[arg-type]
    except TypeError:
        raise NetworkError(f"{network}: ders must be a sequence of DER units, got {ders!r}") from None
    for i, d in enumerate(units):
        if not isinstance(d, DER):
            raise NetworkError(f"{network}: ders[{i}] is {d!r}, not a DER unit")
        if isinstance(d.bus, (bool, np.bool_)) or not isinstance(d.bus, (int, np.integer)):
            raise NetworkError(f"{network}: ders[{i}] has bus {d.bus!r}; a DER's bus is an internal bus index (an integer)")
        for label, value in (("rating_mw", d.rating_mw), ("s_mva", d.s_mva)):
            if value is not None and (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number))):
                raise NetworkError(f"{network}: ders[{i}] has {label} {value!r}; it must be a real number")
        if d.name is not None and not (isinstance(d.name, str) and d.name.strip() and d.name.isprintable()):
            raise NetworkError(f"{network}: ders[{i}] has name {d.name!r}; a DER's name is printable, non-empty text")
    return tuple(d for d in units if isinstance(d, DER))  # every one is


def _number(network: str, name: str, value: object) -> float:
    """`value` as a finite float; NetworkError naming the field otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise NetworkError(f"{network}: {name} must be a real number, got {value!r}")
    number = float(value)
    if not np.isfinite(number):
        raise NetworkError(f"{network}: {name} must be finite, got {number}")
    return number
