"""pandapower as an independent, test-time-only oracle: our Network → ppc → pandapower NR."""

from __future__ import annotations

import warnings

import numpy as np
import pandapower as pp
from pandapower.converter.pypower import from_ppc

from opfbench.io.matpower import to_ppc
from opfbench.network import Network


def pandapower_pf(net: Network, load_scale: float, der_p_mw: np.ndarray, der_q_mvar: np.ndarray):
    """(vm p.u. per bus in our bus order, losses kW, pandapower net) from pandapower's
    Newton–Raphson, the DERs entering as negative load at their buses."""
    ppc = to_ppc(net)
    bus = ppc["bus"]
    bus[:, 2:4] *= load_scale
    np.subtract.at(bus[:, 2], net.der_bus, der_p_mw)
    np.subtract.at(bus[:, 3], net.der_bus, der_q_mvar)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pnet = from_ppc(ppc, f_hz=50)
    pp.runpp(pnet, tolerance_mva=1e-10, init="flat", calculate_voltage_angles=True, numba=False)
    vm = pnet.res_bus.vm_pu.to_numpy()
    losses = (pnet.res_line.pl_mw.sum() + pnet.res_trafo.pl_mw.sum()) * 1e3
    return vm, losses, pnet
