"""pandapower's `runopp` (PIPS interior point, MATPOWER's algorithm) on our networks — the
peer the formulations are timed and cross-checked against.

The pandapower net is built from a MATPOWER case dict of our Network
(`pandapower.converter.from_ppc`): loads from the case (scaled per snapshot), the slack
as ext_grid at `net.v_slack`, each DER a controllable static generator with fixed P
(min_p = max_p = P) and Q in ±(1 − k)·Qmax, cost 1 per MW on the ext_grid's P, so
runopp minimizes the slack import = losses + const. PIPS's default tolerances (1e-6)
stop ~1.5 kW short of the optimum on paper33, so they are tightened to `PIPS_TOLERANCE`
for an equal-accuracy comparison.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from opfbench.io.matpower import to_ppc
from opfbench.network import Network
from opfbench.timing import elapsed_ms, now

PIPS_TOLERANCE = 1e-10
PIPS_OPTIONS = {f"PDIPM_{name}TOL": PIPS_TOLERANCE for name in ("GRAD", "COMP", "COST", "FEAS")}


@dataclass(frozen=True)
class RunoppOutcome:
    """One runopp call: converged flag, branch losses (kW), DER Q (MVAr), wall time (ms)."""

    converged: bool
    losses_kw: float
    q_mvar: np.ndarray
    wall_ms: float


class PandapowerOpf:
    """A pandapower net of `net` with the DERs as controllable sgens; `solve` per snapshot."""

    def __init__(self, net: Network, slack_export: bool = True):
        import pandapower as pp
        from pandapower.converter.pypower import from_ppc

        self._pp = pp
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.pnet = from_ppc(to_ppc(net), f_hz=50, validate_conversion=False)
        self.net = net
        self._load_p = self.pnet.load.p_mw.to_numpy().copy()
        self._load_q = self.pnet.load.q_mvar.to_numpy().copy()
        if not slack_export:
            self.pnet.ext_grid["min_p_mw"] = 0.0
        self._sgens = [
            pp.create_sgen(
                self.pnet,
                self.pnet.bus.index[b],
                p_mw=0.0,
                q_mvar=0.0,
                min_p_mw=0.0,
                max_p_mw=0.0,
                min_q_mvar=0.0,
                max_q_mvar=0.0,
                controllable=True,
            )
            for b in net.der_bus
        ]
        pp.create_poly_cost(self.pnet, self.pnet.ext_grid.index[0], "ext_grid", cp1_eur_per_mw=1.0)

    def solve(self, load_scale: float, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray) -> RunoppOutcome:
        """runopp at one snapshot; failures (non-convergence, exceptions) give converged=False."""
        pnet = self.pnet
        pnet.load["p_mw"] = self._load_p * load_scale
        pnet.load["q_mvar"] = self._load_q * load_scale
        pnet.sgen.loc[self._sgens, "p_mw"] = der_p_mw
        pnet.sgen.loc[self._sgens, "min_p_mw"] = der_p_mw
        pnet.sgen.loc[self._sgens, "max_p_mw"] = der_p_mw
        pnet.sgen.loc[self._sgens, "min_q_mvar"] = -q_limit_mvar
        pnet.sgen.loc[self._sgens, "max_q_mvar"] = q_limit_mvar
        start = now()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._pp.runopp(pnet, delta=1e-10, **PIPS_OPTIONS)
            converged = bool(pnet.OPF_converged)
        except self._pp.OPFNotConverged:
            converged = False
        wall_ms = elapsed_ms(start)
        if not converged:
            return RunoppOutcome(False, np.nan, np.full(len(self._sgens), np.nan), wall_ms)
        losses = (pnet.res_line.pl_mw.sum() + pnet.res_trafo.pl_mw.sum()) * 1e3
        return RunoppOutcome(True, float(losses), pnet.res_sgen.q_mvar.loc[self._sgens].to_numpy(), wall_ms)
