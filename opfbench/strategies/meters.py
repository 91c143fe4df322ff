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

from dataclasses import dataclass

import numpy as np

from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult


@dataclass(frozen=True, eq=False)
class LocalMeters:
    """Meter layout, padded to the largest DER-bus degree m.

    branch (n_der, m): incident branch index (0 in padding); at_from (n_der, m): the DER's
    bus is that branch's from end; valid (n_der, m): a real meter, not padding.
    """

    net: Network
    branch: np.ndarray
    at_from: np.ndarray
    valid: np.ndarray

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

    def outflow_q(self, pf: PowerFlowResult) -> np.ndarray:
        """(S, n_der, m) MVAr: the reactive part of `outflow`."""
        return self.outflow(pf).imag

    def detect_upstream(self, outflow: np.ndarray) -> np.ndarray:
        """(S, n_der) meter position of the line with the largest |Q| (LFMA step 1).
        Ties go to the first line in `Network.incident_branches` order."""
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
