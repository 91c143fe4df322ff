"""Large radial feeders built from case33bw by a fixed rule (`replicated_feeder`).

Rule for `copies` = c ≥ 1 (n_bus = 33·c):
- c copies of case33bw's radial feeder (its 32 in-service branches; the five tie lines
  are left out). Copy k numbers its buses 33·k + (case33bw bus number), so copy 0 keeps
  case33bw's numbering and its substation bus 1 is the slack.
- The substation buses of consecutive copies are joined by a trunk: c − 1 segments, each
  with case33bw's first-branch impedance (bus 1–2) divided by c. Its voltage drop at
  nominal load is then about half that branch's, whatever c.
- Inside each copy, branch impedances are multiplied by c and loads divided by c: each
  copy draws 1/c of case33bw's load through c times its impedance, so its voltage drops
  equal case33bw's and its losses are 1/c of them. The whole feeder draws case33bw's
  3.715 MW + 2.3 MVAr and loses about case33bw's 202.7 kW plus the trunk's.
- DER: in every copy, five units at the buses `place_ders` picks on case33bw (the
  path-resistance quantile rule — the same buses as applying that rule to the copy
  alone), each rated 1/c of what it rates there; limits [0.9, 1.1] p.u., slack 1.0 p.u.

c = 1 gives case33bw itself (with DER as `place_ders` places them). Shipped sizes:
`feeder1k` (c = 30, 990 buses, 150 DER) and `feeder10k` (c = 303, 9 999 buses, 1 515 DER).
"""

from __future__ import annotations

import numpy as np

from opfbench.errors import InputError
from opfbench.network import DER, Network

SHIPPED_COPIES = {"feeder1k": 30, "feeder10k": 303}


def replicated_feeder(base: Network, template: Network, copies: int, name: str) -> Network:
    """The feeder of `copies` copies of `base` (case33bw) by the module's rule; `template`
    is `base` with DER placed by `place_ders` (positions and ratings for c = 1)."""
    if copies < 1:
        raise InputError(f"a replicated feeder needs at least one copy, got {copies}")
    c, n0 = copies, base.n_bus
    on = np.flatnonzero(base.status)
    offset = np.repeat(np.arange(c) * n0, len(on))
    root = base.slack + np.arange(c) * n0
    first = on[np.isin(base.f[on], base.slack) | np.isin(base.t[on], base.slack)][0]
    f = np.concatenate([np.tile(base.f[on], c) + offset, root[:-1]])
    t = np.concatenate([np.tile(base.t[on], c) + offset, root[1:]])
    r = np.concatenate([np.tile(base.r[on], c) * c, np.full(c - 1, base.r[first] / c)])
    x = np.concatenate([np.tile(base.x[on], c) * c, np.full(c - 1, base.x[first] / c)])
    b = np.concatenate([np.tile(base.b[on], c) / c, np.zeros(c - 1)])
    bus_type = np.tile(np.where(np.arange(n0) == base.slack, 1, base.bus_type), c)
    bus_type[base.slack] = 3
    ders = tuple(DER(d.bus + k * n0, d.kind, d.rating_mw / c) for k in range(c) for d in template.ders)
    n_branch = len(f)
    return Network(
        name=name,
        base_mva=base.base_mva,
        bus_ids=(np.arange(c)[:, None] * n0 + base.bus_ids[None, :]).ravel(),
        bus_type=bus_type,
        base_kv=np.tile(base.base_kv, c),
        load_p_mw=np.tile(base.load_p_mw, c) / c,
        load_q_mvar=np.tile(base.load_q_mvar, c) / c,
        gs_mw=np.tile(base.gs_mw, c) / c,
        bs_mvar=np.tile(base.bs_mvar, c) / c,
        vmin=np.tile(template.vmin, c),
        vmax=np.tile(template.vmax, c),
        f=f,
        t=t,
        r=r,
        x=x,
        b=b,
        tap=np.ones(n_branch),
        shift=np.zeros(n_branch),
        status=np.ones(n_branch, dtype=bool),
        slack=int(base.slack),
        v_slack=template.v_slack,
        ders=ders,
    )
