"""Small feeders built directly with the `Network` dataclass, for the local-rule tests."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from opfbench.network import DER, Network


def radial_feeder(
    parent: Sequence[int],
    load_p_mw: Sequence[float],
    load_q_mvar: Sequence[float],
    ders: Sequence[tuple[int, str, float]],
    r: float | Sequence[float] = 1e-4,
    x: float | Sequence[float] = 1e-4,
    reversed_lines: Sequence[int] = (),
    name: str = "test-feeder",
) -> Network:
    """Bus 0 is the slack (1.0 p.u.); bus j ≥ 1 hangs from `parent[j - 1]` by line j − 1.

    Lines run parent → child (from → to) except those in `reversed_lines`, which are stored
    child → parent so that both meter ends are exercised. Base 1 MVA, impedances in p.u.;
    loads MW/MVAr per bus; `ders` = (bus, kind, rating MW).
    """
    n = len(load_q_mvar)
    if len(parent) != n - 1 or len(load_p_mw) != n:
        raise ValueError("parent needs n − 1 entries and load_p_mw n entries")
    child = np.arange(1, n)
    f, t = np.array(parent, dtype=int), child.copy()
    flip = np.array(sorted(reversed_lines), dtype=int)
    f[flip], t[flip] = t[flip], f[flip]
    m = n - 1
    bus_type = np.ones(n, dtype=int)
    bus_type[0] = 3
    return Network(
        name=name,
        base_mva=1.0,
        bus_ids=np.arange(1, n + 1),
        bus_type=bus_type,
        base_kv=np.ones(n),
        load_p_mw=np.asarray(load_p_mw, float),
        load_q_mvar=np.asarray(load_q_mvar, float),
        gs_mw=np.zeros(n),
        bs_mvar=np.zeros(n),
        vmin=np.full(n, 0.9),
        vmax=np.full(n, 1.1),
        f=f,
        t=t,
        r=np.broadcast_to(np.asarray(r, float), (m,)).copy(),
        x=np.broadcast_to(np.asarray(x, float), (m,)).copy(),
        b=np.zeros(m),
        tap=np.ones(m),
        shift=np.zeros(m),
        status=np.ones(m, dtype=bool),
        slack=0,
        ders=tuple(DER(bus, kind, rating) for bus, kind, rating in ders),
    )
