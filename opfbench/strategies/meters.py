"""Local meters: what a DER can measure at its own bus, and nothing else.

Each DER bus has a meter on every in-service line touching it, reading the power that
*leaves the bus into that line*, at the bus's own end of the line (MW + jMVAr). From the
reactive readings alone — no topology — LFMA step 1 picks the upstream line as the one
with the largest |Q| in the no-action state, and later splits the readings into

    Q_up = −(reading on the upstream line)      positive = importing from upstream,
    Q_do = Σ readings on the other lines         positive = exporting downstream.

`Network.parent_branch` (a BFS from the slack) is used only to *check* the detection.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from opfbench.multiphase import GROUND, PhaseNetwork
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult
from opfbench.powerflow.multiphase import PhaseFlowResult, PhaseIterate


class _Readings(ABC):
    """What LFMA does with any meters' readings (`outflow` (S, n_der, m), padded)."""

    branch: np.ndarray
    valid: np.ndarray

    @abstractmethod
    def outflow(self, pf: Any) -> np.ndarray:
        """(S, n_der, m) complex MVA leaving each DER's bus at each meter."""

    def outflow_q(self, pf: Any) -> np.ndarray:
        """(S, n_der, m) MVAr: the reactive part of `outflow`."""
        return self.outflow(pf).imag

    def detect_upstream(self, outflow: np.ndarray) -> np.ndarray:
        """(S, n_der) meter position of the line with the largest |Q| (LFMA step 1).
        Ties go to the first line in meter order."""
        if outflow.shape[-1] == 0:  # no DER (or no metered line): nothing to detect
            return np.zeros(outflow.shape[:-1], dtype=np.int64)
        return np.where(self.valid, np.abs(outflow), -1.0).argmax(axis=-1)

    def upstream_branch(self, position: np.ndarray) -> np.ndarray:
        """(S, n_der) branch index of the line at meter `position`."""
        return self.branch[np.arange(self.branch.shape[0]), position]

    @staticmethod
    def split(outflow: np.ndarray, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q_up, Q_do), each (S, n_der) MVAr, for the upstream line at `position`:
        Q_up > 0 imports from upstream into the bus; Q_do > 0 exports into the other lines."""
        on_up = np.take_along_axis(outflow, position[..., None], axis=-1)[..., 0]
        return -on_up, outflow.sum(axis=-1) - on_up

    @property
    def branch_node(self) -> np.ndarray:
        """(n_der,) bool: the DER has more than one metered line (not a leaf: LFMA steps 3–4)."""
        return self.valid.sum(axis=1) > 1


@dataclass(frozen=True, eq=False)
class LocalMeters(_Readings):
    """Meter layout, padded to the largest DER-bus degree m.

    branch (n_der, m): incident branch index (0 in padding); at_from (n_der, m): the DER's
    bus is that branch's from end; valid (n_der, m): a real meter, not padding.
    """

    net: Network
    branch: np.ndarray
    at_from: np.ndarray
    valid: np.ndarray

    @property
    def branch_node(self) -> np.ndarray:
        return ~self.net.is_leaf[self.net.der_bus]

    @property
    def true_upstream(self) -> np.ndarray:
        """(n_der,) the branch towards the slack (BFS) of each DER's bus (checks LFMA step 1)."""
        return self.net.parent_branch[self.net.der_bus]

    @classmethod
    def of(cls, net: Network) -> "LocalMeters":
        incident = [net.incident_branches[b] for b in net.der_bus]
        m = max((len(i) for i in incident), default=0)
        branch = np.zeros((len(incident), m), dtype=int)
        valid = np.zeros((len(incident), m), dtype=bool)
        for d, lines in enumerate(incident):
            branch[d, : len(lines)] = lines
            valid[d, : len(lines)] = True
        at_from = valid & (net.f[branch] == net.der_bus[:, None])
        return cls(net, branch, at_from, valid)

    def outflow(self, pf: PowerFlowResult) -> np.ndarray:
        """(S, n_der, m) complex MVA leaving each DER bus into each incident line (P + jQ);
        0 in padding and in snapshots whose flow did not converge (nothing to measure)."""
        sf = np.atleast_2d(pf.sf_mva)
        st = np.atleast_2d(pf.st_mva)
        s = np.where(self.at_from, sf[:, self.branch], st[:, self.branch])
        conv = np.atleast_1d(pf.converged)[:, None, None]
        return np.where(self.valid & conv, s, 0.0)


@dataclass(frozen=True, eq=False)
class PhaseMeters(_Readings):
    """Per-phase meters of a three-phase feeder: each DER reads, for every neighbouring bus
    joined to its own by power-delivery elements (lines, switches, transformers), the
    power leaving its bus into those elements on *its own phases' conductors* — one
    conductor for a single-phase unit, three for a three-phase one — at its bus's end
    (MW + jMVAr, summed over the parallel elements to that neighbour and over its phases).
    A meter's `branch` is the neighbouring bus's index.

    rows (R, n_node) sparse: each metered conductor's current (A) as its element's
    primitive admittance row; node (R,): the conductor's node; gather (n_der·m, R) sums
    them into meters; valid (n_der, m); upstream (n_der,): the neighbour towards the source
    (BFS over the elements), −1 where none."""

    net: PhaseNetwork
    branch: np.ndarray
    valid: np.ndarray
    rows: sp.csr_matrix
    node: np.ndarray
    gather: sp.csr_matrix
    upstream: np.ndarray

    @classmethod
    def of(cls, net: PhaseNetwork) -> "PhaseMeters":
        at_bus: dict[int, list[tuple[int, int, int]]] = {}  # bus → (element, terminal, other bus)
        for e, el in enumerate(net.elements):
            if len(set(el.buses)) < 2:
                continue
            for t, b in enumerate(el.buses):
                other = next(o for o in el.buses if o != b)
                at_bus.setdefault(b, []).append((e, t, other))
        meters: list[list[int]] = []  # per DER: its neighbours in meter order
        r_rows: list[int] = []
        r_cols: list[int] = []
        r_vals: list[complex] = []
        nodes: list[int] = []
        g_rows: list[tuple[int, int]] = []
        n_der = len(net.ders)
        per_der: list[dict[int, list[int]]] = []
        for d in range(n_der):
            phases = net.der_phase_nodes[d]
            neighbours: dict[int, list[int]] = {}
            for e, t, other in at_bus.get(int(net.der_bus[d]), []):
                el = net.elements[e]
                n_c = el.nodes.shape[1]
                flat = el.nodes.ravel()
                for c in range(n_c):
                    if int(el.nodes[t, c]) in phases:
                        neighbours.setdefault(other, []).append(len(nodes))
                        keep = flat != GROUND
                        r_rows.extend([len(nodes)] * int(keep.sum()))
                        r_cols.extend(flat[keep].tolist())
                        r_vals.extend(el.yprim[t * n_c + c, keep].tolist())
                        nodes.append(int(el.nodes[t, c]))
            per_der.append(neighbours)
            meters.append(sorted(neighbours))
        m = max((len(x) for x in meters), default=0)
        branch = np.zeros((n_der, m), dtype=int)
        valid = np.zeros((n_der, m), dtype=bool)
        for d, order in enumerate(meters):
            branch[d, : len(order)] = order
            valid[d, : len(order)] = True
            for j, other in enumerate(order):
                g_rows.extend((d * m + j, r) for r in per_der[d][other])
        n_rows = len(nodes)
        rows = sp.csr_matrix((r_vals, (r_rows, r_cols)), shape=(n_rows, net.n_node), dtype=complex)
        gather = sp.csr_matrix(
            (np.ones(len(g_rows)), ([g[0] for g in g_rows], [g[1] for g in g_rows])), shape=(n_der * m, n_rows)
        )
        return cls(net, branch, valid, rows, np.array(nodes, dtype=int), gather, _upstream_bus(net)[net.der_bus])

    def outflow(self, pf: PhaseFlowResult | PhaseIterate) -> np.ndarray:
        """(S, n_der, m) complex MVA leaving each DER's bus on its phases towards each
        neighbour (P + jQ); 0 in padding and where the flow did not converge (an iterate:
        where its iteration did not)."""
        v = np.atleast_2d(pf.v)
        current = self.rows @ v.T  # (R, S) A into the elements
        s = v.T[self.node] * np.conj(current) / 1e6
        n_der, m = self.valid.shape
        out = np.asarray(self.gather @ s).T.reshape(v.shape[0], n_der, m)
        conv = np.atleast_1d(pf.converged if isinstance(pf, PhaseFlowResult) else pf.settled)[:, None, None]
        return np.where(self.valid & conv, out, 0.0)

    @property
    def true_upstream(self) -> np.ndarray:
        return self.upstream


def _upstream_bus(net: PhaseNetwork) -> np.ndarray:
    """(n_bus,) each bus's neighbour towards the source (BFS over the elements), −1 at the
    source bus."""
    pairs = {tuple(sorted(set(e.buses)))[:2] for e in net.elements if len(set(e.buses)) >= 2}
    f = np.array([p[0] for p in pairs], dtype=int)
    t = np.array([p[1] for p in pairs], dtype=int)
    graph = sp.csr_matrix((np.ones(len(f)), (f, t)), shape=(net.n_bus, net.n_bus))
    _, pred = breadth_first_order(graph, net.source.bus, directed=False, return_predecessors=True)
    return np.where(pred < 0, -1, pred)
