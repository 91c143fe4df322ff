"""pandapower's `runopp` (PIPS interior point, MATPOWER's algorithm) on our networks — the
peer the formulations are timed and cross-checked against.

The pandapower net is either built from a MATPOWER case dict of our Network
(`PandapowerOpf.of_network`, `pandapower.converter.from_ppc`: one load per bus with a
nominal load, the slack as ext_grid at `net.v_slack`) or a case's own pandapower net
(`PandapowerOpf.of_simbench`: SimBench's net, transformers and all). Per snapshot every
load element gets its P and Q, each DER is a controllable static generator with fixed P
(min_p = max_p = P) and Q in ±(1 − k)·Qmax, cost 1 per MW on the ext_grid's P, so runopp
minimizes the slack import = losses + const. PIPS's default tolerances (1e-6) stop
~1.5 kW short of the optimum on paper33, so they are tightened to `PIPS_TOLERANCE` for an
equal-accuracy comparison.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from opfbench.io.matpower import to_ppc
from opfbench.network import Network
from opfbench.timing import elapsed_ms, now

PIPS_TOLERANCE = 1e-10
BIG = 1e6  # MW/MVAr: the slack's limits where the net gives none
PIPS_OPTIONS = {f"PDIPM_{name}TOL": PIPS_TOLERANCE for name in ("GRAD", "COMP", "COST", "FEAS")}


@dataclass(frozen=True)
class RunoppOutcome:
    """One runopp call: converged flag, branch losses (kW), DER Q (MVAr), wall time (ms)."""

    converged: bool
    losses_kw: float
    q_mvar: np.ndarray
    wall_ms: float


class PandapowerOpf:
    """A pandapower net `pnet` whose loads `loads` (pandapower index per load element of
    `net`, in its order) and static generators `sgens` (one per DER, in order) are set per
    snapshot; `solve` per snapshot."""

    def __init__(self, pnet, loads: np.ndarray, sgens: list, slack_export: bool = True):
        import pandapower as pp

        self._pp = pp
        self.pnet, self._loads, self._sgens = pnet, np.asarray(loads), list(sgens)
        pnet.sgen.loc[self._sgens, "controllable"] = True
        if "controllable" in pnet.load:
            pnet.load["controllable"] = False
        pnet.ext_grid["controllable"] = True  # the slack, free within ±BIG (SimBench leaves it NaN)
        # a controllable ext_grid's voltage is an OPF variable within its bus's limits: held at
        # its setpoint, as our OPF holds the slack (free, runopp lifts it to Vmax: less loss)
        slack = pnet.ext_grid.bus.to_numpy()
        pnet.bus.loc[slack, "min_vm_pu"] = pnet.bus.loc[slack, "max_vm_pu"] = pnet.ext_grid.vm_pu.to_numpy()
        for column, value in (("min_p_mw", -BIG), ("max_p_mw", BIG), ("min_q_mvar", -BIG), ("max_q_mvar", BIG)):
            known = pnet.ext_grid[column].astype(float) if column in pnet.ext_grid else None
            pnet.ext_grid[column] = known.fillna(value) if known is not None else value
        if not slack_export:
            pnet.ext_grid["min_p_mw"] = 0.0
        pp.create_poly_cost(pnet, pnet.ext_grid.index[0], "ext_grid", cp1_eur_per_mw=1.0)

    @classmethod
    def of_network(cls, net: Network, slack_export: bool = True) -> "PandapowerOpf":
        """The peer on `net` as a MATPOWER case (DER added as static generators)."""
        import pandapower as pp
        from pandapower.converter.pypower import from_ppc

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pnet = from_ppc(to_ppc(net), f_hz=50, validate_conversion=False)
        if not np.array_equal(pnet.load.bus.to_numpy(), pnet.bus.index[net.load_bus].to_numpy()):
            raise ValueError(f"{net.name}: the peer needs one load per bus with a nominal load (the MATPOWER convention)")
        sgens = [
            pp.create_sgen(
                pnet, pnet.bus.index[b], p_mw=0.0, q_mvar=0.0, min_p_mw=0.0, max_p_mw=0.0, min_q_mvar=0.0, max_q_mvar=0.0
            )
            for b in net.der_bus
        ]
        return cls(pnet, pnet.load.index.to_numpy(), sgens, slack_export)

    @classmethod
    def of_simbench(cls, code: str, load_index: np.ndarray, der_index: np.ndarray, slack_export: bool = True) -> "PandapowerOpf":
        """The peer on SimBench's own net of `code` (taps active as opfbench reads them),
        with what our OPF does not have taken out: the lines' and transformers' loading
        limits, and the transformers' 150° phase shift, which only rotates the angles of a
        radial grid (runopp does not converge with it: PIPS from any start we tried);
        `load_index` / `der_index`: the case's pandapower load and sgen rows, in order."""
        from opfbench.io.simbench import simbench_net

        pnet = simbench_net(code)[0]
        pnet.line["max_loading_percent"] = pnet.trafo["max_loading_percent"] = 1e5
        pnet.trafo["shift_degree"] = 0.0
        return cls(pnet, load_index, list(der_index), slack_export)

    def solve(
        self, load_p_mw: np.ndarray, load_q_mvar: np.ndarray, der_p_mw: np.ndarray, q_limit_mvar: np.ndarray
    ) -> RunoppOutcome:
        """runopp at one snapshot (per load element P/Q, per DER P and Q limit); failures
        (non-convergence, exceptions) give converged=False."""
        pnet = self.pnet
        pnet.load.loc[self._loads, "p_mw"] = load_p_mw
        pnet.load.loc[self._loads, "q_mvar"] = load_q_mvar
        pnet.load.loc[self._loads, "scaling"] = 1.0
        sg = self._sgens
        pnet.sgen.loc[sg, "scaling"] = 1.0
        for column in ("p_mw", "min_p_mw", "max_p_mw"):
            pnet.sgen.loc[sg, column] = der_p_mw
        pnet.sgen.loc[sg, "min_q_mvar"] = -q_limit_mvar
        pnet.sgen.loc[sg, "max_q_mvar"] = q_limit_mvar
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
            return RunoppOutcome(False, np.nan, np.full(len(sg), np.nan), wall_ms)
        losses = (pnet.res_line.pl_mw.sum() + pnet.res_trafo.pl_mw.sum()) * 1e3
        return RunoppOutcome(True, float(losses), pnet.res_sgen.q_mvar.loc[sg].to_numpy(), wall_ms)
