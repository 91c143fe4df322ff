"""pandapower as an independent, test-time-only oracle: our Network → ppc → pandapower."""

from __future__ import annotations

import numpy as np
from pandapower.converter.pypower import from_ppc
import pandapower as pp

from opfbench.network import Network


def to_ppc(net: Network, load_scale: float, der_p_mw: np.ndarray, der_q_mvar: np.ndarray) -> dict:
    """MATPOWER-style dict with DERs added to the bus loads as negative demand."""
    n = net.n_bus
    pd = load_scale * net.load_p_mw.copy()
    qd = load_scale * net.load_q_mvar.copy()
    np.subtract.at(pd, net.der_bus, der_p_mw)
    np.subtract.at(qd, net.der_bus, der_q_mvar)
    bus = np.zeros((n, 13))
    bus[:, 0] = np.arange(1, n + 1)
    bus[:, 1] = net.bus_type
    bus[:, 2], bus[:, 3] = pd, qd
    bus[:, 4], bus[:, 5] = net.gs_mw, net.bs_mvar
    bus[:, 6] = 1
    bus[:, 7] = 1.0
    bus[:, 9] = net.base_kv
    bus[:, 10] = 1
    bus[:, 11], bus[:, 12] = 1.1, 0.9
    gen = np.zeros((1 + len(net.gen_bus), 21))
    gen[0, [0, 5, 6, 7, 8, 3, 4]] = [net.slack + 1, net.v_slack, net.base_mva, 1, 100, 100, -100]
    for row, (b, p, q, vs) in enumerate(zip(net.gen_bus, net.gen_p_mw, net.gen_q_mvar, net.gen_vset), start=1):
        gen[row, [0, 1, 2, 5, 6, 7, 8, 3, 4]] = [b + 1, p, q, vs, net.base_mva, 1, 100, 100, -100]
    branch = np.zeros((net.n_branch, 13))
    branch[:, 0], branch[:, 1] = net.f + 1, net.t + 1
    branch[:, 2], branch[:, 3], branch[:, 4] = net.r, net.x, net.b
    branch[:, 8] = np.where(net.tap == 1.0, 0.0, net.tap)
    branch[:, 9] = net.shift
    branch[:, 10] = net.status
    branch[:, 11], branch[:, 12] = -360, 360
    return {"version": "2", "baseMVA": net.base_mva, "bus": bus, "gen": gen, "branch": branch}


def pandapower_pf(net: Network, load_scale: float, der_p_mw: np.ndarray, der_q_mvar: np.ndarray):
    """(vm p.u. per bus in our bus order, losses kW) from pandapower's Newton–Raphson."""
    pnet = from_ppc(to_ppc(net, load_scale, der_p_mw, der_q_mvar), f_hz=50)
    pp.runpp(pnet, tolerance_mva=1e-10, init="flat", calculate_voltage_angles=True)
    vm = pnet.res_bus.vm_pu.to_numpy()
    losses = (pnet.res_line.pl_mw.sum() + pnet.res_trafo.pl_mw.sum()) * 1e3
    return vm, losses, pnet
