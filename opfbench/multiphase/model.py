"""`PhaseNetwork`: an unbalanced feeder at node level, as OpenDSS compiled it.

Nodes are OpenDSS's (`bus.phase`, phase 1, 2, 3 and neutrals 4…; its node 0, ground, is
not a node here: `GROUND`). Every array indexed by node uses the node order of
`node_bus`/`node_phase` (OpenDSS's own system node order when read from a file).
Units: volts, amperes, siemens, ohms; powers in MW/MVAr as everywhere in opfbench
(positive = consumed for loads, generated for DER).

What the model holds, element by element (what a power flow, a branch-flow OPF or a
linearised model needs):

- `elements`: every power-delivery element (lines and switches, transformers and
  regulators at their taps, capacitors, reactors) with its terminals' nodes and its
  primitive admittance `yprim` — OpenDSS's own element model, so every transformer
  connection (wye/delta, single-phase, centre-tapped) is right by construction. The bus
  admittance matrix is their sum (`y_elements`), ground rows and columns dropped.
- `lines`: for each line (and switch) its series impedance matrix Z (Ω) and total shunt
  admittance matrix Y (S, half at each end) in its conductors' order — the π model whose
  primitive admittance is the element's (Z = (−Y_prim[terminal 1, terminal 2])⁻¹) — and its
  length.
- `transformers`: windings (connection, rated kV and kVA, tap at the settled position,
  %R), the leakage reactances, and whether a regulator control acts on it.
- `source`: the upstream grid as an ideal EMF `emf_v` behind its Thevenin admittance
  `y_s` at the source bus's nodes (OpenDSS's Vsource); a formulation that fixes the
  source's three phase voltages fixes the EMF nodes behind that admittance.
- `load_branches`, `load_models` and the nominal powers `load_p_mw`/`load_q_mvar` of each
  load element (`opfbench.multiphase.branches`: wye, delta, split-phase; OpenDSS models
  1, 2, 4, 5 with their switches to impedance); loads are not in the admittance matrix.
  `load_fixed`: the loads a load multiplier leaves at their nominal (OpenDSS `status=fixed`
  or `exempt`; `loads_at`).
- `ders` and `der_branches`: DER as constant-power branches the same way.
- `band`: the case's voltage band (p.u.) and the voltages it applies to (`monitored`):
  phase-to-neutral at the phase nodes of buses whose section (buses joined by lines) has a
  ground reference other than line capacitance, phase-to-phase on three-wire delta
  sections (where phase-to-neutral voltages are not defined).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from opfbench.errors import NetworkError
from opfbench.multiphase.branches import GROUND, Branches, LoadModels
from opfbench.multiphase.regulators import Regulator
from opfbench.network import DER, DerFleet

ELEMENT_KINDS = ("line", "transformer", "capacitor", "reactor")
PHASES = (1, 2, 3)
"""OpenDSS's phase node numbers; higher node numbers are neutrals."""


def _frozen(arr: object, dtype: type | None = None) -> np.ndarray:
    out = np.array(arr, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Element:
    """A power-delivery element: `name` as OpenDSS prints it (`Line.650632`), `kind` one of
    ELEMENT_KINDS, `buses` the bus of each terminal, `nodes` (terminals, conductors) the
    node of each conductor (GROUND for node 0), `yprim` its primitive admittance (S) in the
    order of `nodes.ravel()`."""

    name: str
    kind: str
    buses: tuple[int, ...]
    nodes: np.ndarray
    yprim: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", _frozen(self.nodes, int))
        object.__setattr__(self, "yprim", _frozen(self.yprim, complex))


@dataclass(frozen=True, eq=False)
class Line:
    """A line or switch (`elements[element]`): series impedance `z_ohm` and total shunt
    admittance `y_shunt_s` (half at each end), both (conductors, conductors) complex in the
    order of the element's conductors; `length_km` (NaN where the file gives no unit)."""

    element: int
    z_ohm: np.ndarray
    y_shunt_s: np.ndarray
    length_km: float
    switch: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "z_ohm", _frozen(self.z_ohm, complex))
        object.__setattr__(self, "y_shunt_s", _frozen(self.y_shunt_s, complex))


@dataclass(frozen=True)
class Winding:
    """A transformer winding: `conn` "wye" or "delta", rated `kv` (phase-to-phase for two-
    and three-phase transformers, the winding's own voltage for one-phase ones), `kva`,
    `tap` (p.u., at the settled position), `r_pct` (% on the winding's kVA), and the tap
    changer's range (`min_tap`, `max_tap` p.u., `num_taps` steps)."""

    conn: str
    kv: float
    kva: float
    tap: float
    r_pct: float
    min_tap: float
    max_tap: float
    num_taps: int


@dataclass(frozen=True)
class Transformer:
    """A transformer or regulator (`elements[element]`): `phases`, `windings`, leakage
    reactances `x_pct` (XHL, XHT, XLT in % on winding 1's kVA; one value for two windings),
    `regulated` when a regulator control (RegControl) acts on it."""

    element: int
    phases: int
    windings: tuple[Winding, ...]
    x_pct: tuple[float, ...]
    regulated: bool


@dataclass(frozen=True, eq=False)
class Source:
    """The upstream grid: an EMF `emf_v` (complex V per node) behind the Thevenin admittance
    `y_s` (S) at the nodes `nodes` of bus `bus` — its Norton current `y_s @ emf_v` is injected
    there and `y_s` is part of the bus admittance matrix."""

    name: str
    bus: int
    nodes: np.ndarray
    y_s: np.ndarray
    emf_v: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", _frozen(self.nodes, int))
        object.__setattr__(self, "y_s", _frozen(self.y_s, complex))
        object.__setattr__(self, "emf_v", _frozen(self.emf_v, complex))


@dataclass(frozen=True, eq=False)
class PhaseNetwork(DerFleet):
    """An unbalanced feeder at node level (see the module docstring). Buses: `bus_names`
    (lower case, OpenDSS's), `bus_kv_ln` (n_bus,) phase-to-neutral base kV. Nodes:
    `node_bus`, `node_phase` (n_node,). Loads: `load_names` (OpenDSS's `Load.x`), `load_bus`,
    nominal `load_p_mw`, `load_q_mvar` (n_load,), `load_models`, `load_branches`, `load_fixed`. DER:
    `ders` (`DER.bus` a bus index), `der_names`, `der_branches`. `band` (low, high) p.u. and
    `band_name` (the standard it is from). `regulators` (read with `?taps=control`): the
    RegControls with their transformers' admittance at every tap position; `tap_control`
    the power flow moves their taps as OpenDSS's static control would
    (`opfbench.multiphase.regulators`), else the taps stay where the elements have them.

    Checked on construction: array shapes, node and bus indices, positive base voltages at
    every node a load, DER or monitored voltage uses, finite admittances, and that every
    node is connected to the source through the elements (islanded nodes are refused,
    named)."""

    name: str
    frequency_hz: float
    bus_names: tuple[str, ...]
    bus_kv_ln: np.ndarray
    node_bus: np.ndarray
    node_phase: np.ndarray
    elements: tuple[Element, ...]
    lines: tuple[Line, ...]
    transformers: tuple[Transformer, ...]
    source: Source
    load_names: tuple[str, ...]
    load_bus: np.ndarray
    load_p_mw: np.ndarray
    load_q_mvar: np.ndarray
    load_models: LoadModels
    load_branches: Branches
    ders: tuple[DER, ...] = ()
    der_names: tuple[str, ...] = ()
    der_branches: Branches = field(default_factory=Branches.empty)
    band: tuple[float, float] = (0.95, 1.05)
    band_name: str = "ANSI C84.1 Range A"
    regulators: tuple[Regulator, ...] = ()
    tap_control: bool = False
    load_fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        if np.size(self.load_fixed) == 0:
            object.__setattr__(self, "load_fixed", np.zeros(len(self.load_names), dtype=bool))
        for name, dtype in (
            ("bus_kv_ln", float),
            ("node_bus", int),
            ("node_phase", int),
            ("load_bus", int),
            ("load_p_mw", float),
            ("load_q_mvar", float),
            ("load_fixed", bool),
        ):
            object.__setattr__(self, name, _frozen(getattr(self, name), dtype))
        self._check()

    # ----- checks --------------------------------------------------------------------
    def _refuse(self, problem: str) -> None:
        raise NetworkError(f"{self.name}: {problem}")

    def _check(self) -> None:
        n_bus, n_node = len(self.bus_names), len(self.node_bus)
        if self.bus_kv_ln.shape != (n_bus,):
            self._refuse(f"bus_kv_ln has shape {self.bus_kv_ln.shape}, expected ({n_bus},)")
        if self.node_phase.shape != (n_node,):
            self._refuse(f"node_phase has shape {self.node_phase.shape}, expected ({n_node},)")
        if n_node and (self.node_bus.min() < 0 or self.node_bus.max() >= n_bus):
            self._refuse("node_bus refers to a bus outside the bus list")
        n_load = len(self.load_names)
        for name in ("load_bus", "load_p_mw", "load_q_mvar", "load_fixed"):
            if getattr(self, name).shape != (n_load,):
                self._refuse(f"{name} has shape {getattr(self, name).shape}, expected ({n_load},) like load_names")
        if self.load_branches.n_owner != n_load or len(self.load_models.model) != n_load:
            self._refuse("load_branches and load_models must describe every load element")
        if len(self.der_names) != len(self.ders) or self.der_branches.n_owner != len(self.ders):
            self._refuse("der_names and der_branches must describe every DER")
        if len(set(self.der_names)) != len(self.der_names):
            self._refuse("DER names must be unique")
        for label, br in (("load", self.load_branches), ("DER", self.der_branches)):
            if br.n and (br.a.min() < 0 or br.a.max() >= n_node or br.b.min() < GROUND or br.b.max() >= n_node):
                self._refuse(f"a {label} branch refers to a node outside 0..{n_node - 1}")
            if not np.all(br.vbase_v > 0):
                self._refuse(f"a {label} branch has no positive base voltage")
        for e in self.elements:
            if e.kind not in ELEMENT_KINDS:
                self._refuse(f"element {e.name} has kind {e.kind!r}; expected one of {', '.join(ELEMENT_KINDS)}")
            size = e.nodes.size
            if e.yprim.shape != (size, size) or not np.all(np.isfinite(e.yprim)):
                self._refuse(f"element {e.name}: its primitive admittance is not a finite {size}×{size} matrix")
            if e.nodes.size and (e.nodes.min() < GROUND or e.nodes.max() >= n_node):
                self._refuse(f"element {e.name} refers to a node outside 0..{n_node - 1}")
        lo, hi = self.band
        if not 0 < lo < hi:
            self._refuse(f"voltage band {lo:g}–{hi:g} p.u. is not a band (0 < low < high)")
        used = np.concatenate([self.load_branches.a, self.der_branches.a, self.monitored[0]])
        no_base = np.flatnonzero(self.node_base_v[used] <= 0)
        if no_base.size:
            self._refuse(f"node {self.node_names[used[no_base[0]]]} has no base voltage (set voltagebases and calcvoltagebases)")
        self._check_islands()

    def _check_islands(self) -> None:
        """Every node is joined to the source's nodes by the elements' admittances."""
        pattern = abs(self.y_elements) + sp.csr_matrix(
            (np.ones(len(self.source.nodes)), (self.source.nodes, np.full(len(self.source.nodes), self.source.nodes[0]))),
            shape=(self.n_node, self.n_node),
        )
        _, label = connected_components(pattern, directed=False)
        islanded = np.flatnonzero(label != label[self.source.nodes[0]])
        if islanded.size:
            names = ", ".join(self.node_names[i] for i in islanded[:20])
            self._refuse(
                f"{islanded.size} node(s) islanded from the source {self.source.name} by the enabled elements: {names}"
                + (" …" if islanded.size > 20 else "")
            )

    def with_tap_positions(self, positions: tuple[int, ...]) -> "PhaseNetwork":
        """This network with each regulator's transformer at tap position `positions[i]`
        (indices into `Regulator.taps`) and the taps held there (no tap control)."""
        elements = list(self.elements)
        for reg, pos in zip(self.regulators, positions, strict=True):
            e = elements[reg.element]
            elements[reg.element] = Element(e.name, e.kind, e.buses, e.nodes, reg.yprims[pos])
        return replace(self, elements=tuple(elements), tap_control=False)

    # ----- sizes and names -----------------------------------------------------------
    @property
    def n_bus(self) -> int:
        return len(self.bus_names)

    @property
    def n_node(self) -> int:
        return len(self.node_bus)

    @property
    def n_load(self) -> int:
        return len(self.load_names)

    def loads_at(self, scale: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(P (S, n_load) MW, Q (S, n_load) MVAr) of every load element at the load
        multiplier `scale` (S,) — OpenDSS's `loadmult`, or a load profile that acts as one:
        each load's nominal × the multiplier, a `load_fixed` one at its nominal."""
        mult = np.where(self.load_fixed[None, :], 1.0, np.atleast_1d(np.asarray(scale, dtype=float))[:, None])
        return mult * self.load_p_mw[None, :], mult * self.load_q_mvar[None, :]

    @cached_property
    def node_names(self) -> tuple[str, ...]:
        """`bus.phase` of every node, lower case (OpenDSS's node names)."""
        return tuple(f"{self.bus_names[b]}.{p}" for b, p in zip(self.node_bus.tolist(), self.node_phase.tolist(), strict=True))

    @cached_property
    def node_base_v(self) -> np.ndarray:
        """(n_node,) each node's phase-to-neutral base voltage, V."""
        return _frozen(self.bus_kv_ln[self.node_bus] * 1e3)

    # ----- DER as every rule and limit reads them (`network.DerFleet`, and as below) ----
    @property
    def bus_ids(self) -> np.ndarray:
        """(n_bus,) the buses' OpenDSS names (what a result names a DER's bus by)."""
        return np.array(self.bus_names, dtype=object)

    @cached_property
    def der_phase_nodes(self) -> tuple[frozenset[int], ...]:
        """Each DER's phase nodes (the nodes its branches start from: one for a
        single-phase unit, three for a three-phase one)."""
        nodes: list[set[int]] = [set() for _ in self.ders]
        for owner, a in zip(self.der_branches.owner.tolist(), self.der_branches.a.tolist(), strict=True):
            nodes[owner].add(a)
        return tuple(frozenset(n) for n in nodes)

    @cached_property
    def der_share(self) -> np.ndarray:
        """(n_der,) each DER's share of what it measures on its phases (the flows on its
        phases' conductors): S̄ / Σ S̄ of the DER on the same phase nodes — 1 for a DER
        alone there (`Network.der_share`, per phase)."""
        s = self.der_s_mva
        groups: dict[frozenset[int], float] = {}
        for key, rated in zip(self.der_phase_nodes, s.tolist(), strict=True):
            groups[key] = groups.get(key, 0.0) + rated
        return _frozen(np.array([rated / groups[key] for key, rated in zip(self.der_phase_nodes, s.tolist(), strict=True)]))

    @cached_property
    def der_load_weights(self) -> sp.csr_matrix:
        """(n_der, n_load): the load each DER measures (LLMA's own-bus load) as weights of
        the load elements' powers — the load on the DER's phases: each load branch whose
        phase node is one of a DER's phase nodes, shared among the DER on that node in
        proportion to their S̄ per phase (S̄ / phases). Several DER on one phase together
        compensate its load once; a three-phase unit takes the load of all three."""
        db, lb = self.der_branches, self.load_branches
        per_branch = self.der_s_mva[db.owner] * db.share  # S̄ per phase of each DER branch
        on_node: dict[int, list[tuple[int, float]]] = {}
        for owner, a, rated in zip(db.owner.tolist(), db.a.tolist(), per_branch.tolist(), strict=True):
            on_node.setdefault(a, []).append((owner, rated))
        rows, cols, vals = [], [], []
        for owner, a, share in zip(lb.owner.tolist(), lb.a.tolist(), lb.share.tolist(), strict=True):
            units = on_node.get(a, ())
            total = sum(r for _, r in units)
            for der, rated in units:
                rows.append(der)
                cols.append(owner)
                vals.append(share * rated / total)
        w = sp.csr_matrix((vals, (rows, cols)), shape=(len(self.ders), self.n_load))
        w.sum_duplicates()
        return w

    @cached_property
    def der_measure(self) -> sp.csr_matrix:
        """(n_der, n_der_branch): each DER's measured voltage as the average of its
        branches' voltages in p.u. of their bases (a single-phase unit: its own; a
        three-phase unit: the average of its phases, OpenDSS InvControl's default AVG)."""
        db = self.der_branches
        count = np.bincount(db.owner, minlength=len(self.ders)).astype(float)
        return sp.csr_matrix((1.0 / count[db.owner], (db.owner, np.arange(db.n))), shape=(len(self.ders), db.n))

    @cached_property
    def origin(self) -> PhaseNetwork:
        """The feeder this one was derived from by `with_band` (itself if none): the two
        differ in their band only, so what is built for one (a compiled OPF) serves both."""
        return self

    def with_band(self, low: float, high: float) -> PhaseNetwork:
        """This feeder with the voltage band (low, high) p.u. (0 ≤ low < high; low 0 is
        the physical limit alone): a copy that shares every derived matrix with this one
        (none depends on the band), `origin` this one's. ValueError for no band."""
        if not 0 <= low < high:
            raise ValueError(f"{self.name}: voltage band {low:g}–{high:g} p.u. is not a band (0 ≤ low < high)")
        out = copy.copy(self)  # the cached derived matrices come along; the checks passed for this one
        object.__setattr__(out, "band", (float(low), float(high)))
        out.__dict__["origin"] = self.origin
        return out

    @property
    def vmin(self) -> np.ndarray:
        """(n_monitored,) the band's lower limit at every monitored voltage, p.u."""
        return np.full(len(self.monitored[0]), self.band[0])

    @property
    def vmax(self) -> np.ndarray:
        """(n_monitored,) the band's upper limit at every monitored voltage, p.u."""
        return np.full(len(self.monitored[0]), self.band[1])

    # ----- admittances ---------------------------------------------------------------
    @cached_property
    def y_elements(self) -> sp.csc_matrix:
        """(n_node, n_node) the power-delivery elements' admittances summed (S), ground
        dropped; the source's Thevenin admittance is not in it (`ybus`)."""
        rows, cols, vals = [], [], []
        for e in self.elements:
            nodes = e.nodes.ravel()
            keep = np.flatnonzero(nodes != GROUND)
            r, c = np.meshgrid(nodes[keep], nodes[keep], indexing="ij")
            rows.append(r.ravel())
            cols.append(c.ravel())
            vals.append(e.yprim[np.ix_(keep, keep)].ravel())
        y = sp.csc_matrix(
            (np.concatenate(vals or [np.zeros(0, complex)]), (np.concatenate(rows or [[]]), np.concatenate(cols or [[]]))),
            shape=(self.n_node, self.n_node),
        )
        y.sum_duplicates()
        return y

    @cached_property
    def ybus(self) -> sp.csc_matrix:
        """(n_node, n_node) bus admittance matrix (S): the elements' plus the source's
        Thevenin admittance at its nodes."""
        s = self.source
        r, c = np.meshgrid(s.nodes, s.nodes, indexing="ij")
        y_src = sp.csc_matrix((s.y_s.ravel(), (r.ravel(), c.ravel())), shape=(self.n_node, self.n_node))
        return (self.y_elements + y_src).tocsc()

    @cached_property
    def source_current(self) -> np.ndarray:
        """(n_node,) the source's Norton current y_s·E (A) at its nodes, 0 elsewhere."""
        out = np.zeros(self.n_node, dtype=complex)
        out[self.source.nodes] = self.source.y_s @ self.source.emf_v
        out.setflags(write=False)
        return out

    # ----- voltages the band applies to, unbalance -----------------------------------
    @cached_property
    def grounded_bus(self) -> np.ndarray:
        """(n_bus,) bool: the bus's section (buses joined by lines and switches) has a
        ground reference — the source, or an element other than a line, or a load or DER
        branch, connected to ground (node 0) at one of its buses (a conductor on node 0
        that its element's admittance does not use, e.g. a delta winding's, is none)."""
        referenced = np.zeros(self.n_bus, dtype=bool)
        referenced[self.source.bus] = True
        for e in self.elements:
            if e.kind != "line":
                grounds = (e.nodes.ravel() == GROUND) & (np.abs(e.yprim).sum(axis=1) > 0)  # a delta winding's neutral: no row
                for term, bus in enumerate(e.buses):
                    referenced[bus] |= bool(grounds.reshape(e.nodes.shape)[term].any())
        for br in (self.load_branches, self.der_branches):
            referenced[self.node_bus[br.a[br.b == GROUND]]] = True
        line_buses = [e.buses for e in self.elements if e.kind == "line" and len(e.buses) == 2]
        f = np.array([b[0] for b in line_buses], dtype=int)
        t = np.array([b[1] for b in line_buses], dtype=int)
        graph = sp.csr_matrix((np.ones(len(f)), (f, t)), shape=(self.n_bus, self.n_bus))
        n_sections, section = connected_components(graph, directed=False)
        grounded_section = np.zeros(n_sections, dtype=bool)
        np.logical_or.at(grounded_section, section, referenced)
        return _frozen(grounded_section[section])

    @cached_property
    def monitored(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...]]:
        """The voltages the band applies to: (a, b, base_v, names) — node a against node b
        (GROUND, the bus's neutral, or another phase), base (V), names `bus.1` for
        phase-to-neutral and `bus.1-2` for phase-to-phase (module docstring)."""
        a: list[int] = []
        b: list[int] = []
        base: list[float] = []
        names: list[str] = []
        nodes_of: dict[int, dict[int, int]] = {}
        for i, (bus, phase) in enumerate(zip(self.node_bus.tolist(), self.node_phase.tolist(), strict=True)):
            nodes_of.setdefault(bus, {})[phase] = i
        for bus in range(self.n_bus):
            nodes = nodes_of.get(bus, {})
            phases = [p for p in PHASES if p in nodes]
            kv = self.bus_kv_ln[bus] * 1e3
            if self.grounded_bus[bus]:
                neutral = min((p for p in nodes if p not in PHASES), default=None)
                for p in phases:
                    a.append(nodes[p])
                    b.append(GROUND if neutral is None else nodes[neutral])
                    base.append(kv)
                    names.append(f"{self.bus_names[bus]}.{p}")
            else:
                pairs = [(1, 2), (2, 3), (3, 1)] if len(phases) == 3 else [tuple(phases)] if len(phases) == 2 else []
                for p, q in pairs:
                    a.append(nodes[p])
                    b.append(nodes[q])
                    base.append(kv * np.sqrt(3.0))
                    names.append(f"{self.bus_names[bus]}.{p}-{q}")
        return (_frozen(a, int), _frozen(b, int), _frozen(base, float), tuple(names))

    @cached_property
    def bus_distance(self) -> tuple[np.ndarray, np.ndarray]:
        """(distance_km, upstream) per bus: the length of the shortest path from the
        source's bus along the elements joining buses (lines at their length, a line
        without a length unit and any other element at 0 km), and the bus before it on that
        path (−1 for the source's bus and for a bus no path reaches, whose distance is NaN)
        — the x axis of a voltage profile (OpenDSS's `plot profile`)."""
        from scipy.sparse.csgraph import dijkstra

        length = {line.element: line.length_km for line in self.lines}
        edges: dict[tuple[int, int], float] = {}  # parallel elements: the shortest
        for i, e in enumerate(self.elements):
            if len(set(e.buses)) == 2:
                km = length.get(i, 0.0)
                key = (min(e.buses), max(e.buses))
                edges[key] = min(edges.get(key, np.inf), km if np.isfinite(km) and km > 0 else 1e-9)  # 0 would be no edge
        f, t = (np.array([k[j] for k in edges], dtype=int) for j in (0, 1))
        graph = sp.csr_matrix((list(edges.values()), (f, t)), shape=(self.n_bus, self.n_bus))
        dist, pred = dijkstra(graph, directed=False, indices=self.source.bus, return_predecessors=True)
        dist = np.where(np.isfinite(dist), dist, np.nan)
        return _frozen(dist), _frozen(np.where(pred < 0, -1, pred), int)

    @cached_property
    def three_phase_nodes(self) -> np.ndarray:
        """(n, 3) the phase nodes 1, 2, 3 of every bus that has all three (VUF)."""
        nodes: dict[int, dict[int, int]] = {}
        for i, (bus, phase) in enumerate(zip(self.node_bus.tolist(), self.node_phase.tolist(), strict=True)):
            nodes.setdefault(bus, {})[phase] = i
        rows = [[n[p] for p in PHASES] for _, n in sorted(nodes.items()) if all(p in n for p in PHASES)]
        return _frozen(np.array(rows, dtype=int).reshape(-1, 3))

    @cached_property
    def meshed(self) -> bool:
        """True when the elements joining two buses form a loop between buses (parallel
        single-phase units between the same two buses, e.g. a regulator bank, are one
        connection)."""
        pairs = {tuple(sorted(e.buses)) for e in self.elements if len(set(e.buses)) == 2}
        f = np.array([p[0] for p in pairs], dtype=int)
        t = np.array([p[1] for p in pairs], dtype=int)
        n_comp, _ = connected_components(sp.csr_matrix((np.ones(len(f)), (f, t)), shape=(self.n_bus, self.n_bus)), directed=False)
        return len(pairs) > self.n_bus - n_comp

    def summary(self) -> dict:
        return {
            "case": self.name,
            "buses": self.n_bus,
            "nodes": self.n_node,
            "branches": sum(1 for e in self.elements if len(set(e.buses)) == 2),
            "ders": len(self.ders),
            "loads": self.n_load,
            "meshed": self.meshed,
            "load_mw": float(self.load_p_mw.sum()),
            "load_mvar": float(self.load_q_mvar.sum()),
            "band_pu": list(self.band),
        }
