"""Cases shipped with opfbench, by name.

- `case33bw`, `case69`, `case141`: MATPOWER's distribution feeders as published (no DER).
- `paper33`: the paper's modified IEEE 33-bus feeder (paper §IV): case33bw with PV inverters
  at buses 10, 16, 19, 29 and a DFIG at bus 27, each rated 0.6 MW; slack 1.0 p.u.;
  voltage limits [0.9, 1.1] p.u. on every bus (slack included); the five tie lines open.
- `paper33-meshed`: the same with the five tie lines closed.
- `case69-der`, `case141-der`: DER placed by `place_ders` (rule below), to test the
  paper's claim that the rules work on any feeder.
- `feeder1k`, `feeder10k`: large radial feeders (990 and 9 999 buses), copies of
  case33bw on a stiff trunk with DER in every copy (`opfbench.cases.feeder`);
  `feeder(c)` builds the same rule for any number of copies c.

Cases are loaded by spec through `opfbench.io.load_case` (shipped names, files, SimBench).
"""

from __future__ import annotations

from functools import lru_cache, partial
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from opfbench.cases.feeder import SHIPPED_COPIES, replicated_feeder
from opfbench.io.matpower import load_case_file
from opfbench.network import DER, DerKind, Network

PAPER_PV_BUSES = (10, 16, 19, 29)
PAPER_DFIG_BUS = 27
PAPER_DER_RATING_MW = 0.6


def _matpower_file(stem: str) -> Path:
    return Path(str(resources.files("opfbench.cases") / "matpower" / f"{stem}.m"))


def _paper_limits(net: Network) -> Network:
    n = net.n_bus
    return net.with_changes(vmin=np.full(n, 0.9), vmax=np.full(n, 1.1), v_slack=1.0)


def _paper33(meshed: bool) -> Network:
    base = load_case_file(_matpower_file("case33bw"), "paper33-meshed" if meshed else "paper33")
    ders = tuple(DER(base.index_of(b), "PV", PAPER_DER_RATING_MW) for b in PAPER_PV_BUSES)
    ders += (DER(base.index_of(PAPER_DFIG_BUS), "DFIG", PAPER_DER_RATING_MW),)
    status = np.ones(base.n_branch, dtype=bool) if meshed else base.status
    return _paper_limits(base.with_changes(ders=ders, status=status))


def place_ders(net: Network, name: str) -> Network:
    """Place five DER units as on the paper feeder, by a rule that works on any radial case.

    Rule: rank the load buses by the resistance of their path from the slack; put units at
    the buses nearest the 30 %, 45 %, 60 %, 75 % and 90 % quantiles of that ranking
    (distinct buses); kinds PV, PV, PV, DFIG, PV; each rated one fifth of 80.75 % of the
    case's total active load (the paper feeder's 3.0 MW of DER over 3.715 MW of load).
    Voltage limits [0.9, 1.1] p.u., slack at 1.0 p.u.
    """
    path_r = np.zeros(net.n_bus)
    for j in net.bfs_order[1:]:
        path_r[j] = path_r[net.parent[j]] + net.r[net.parent_branch[j]]
    loads = np.flatnonzero(net.load_p_mw > 0)
    ranked = loads[np.argsort(path_r[loads], kind="stable")]
    picks: list[int] = []
    for q in (0.30, 0.45, 0.60, 0.75, 0.90):
        k = int(round(q * (len(ranked) - 1)))
        while int(ranked[k]) in picks:
            k += 1
        picks.append(int(ranked[k]))
    rating = 0.8075 * float(net.load_p_mw.sum()) / 5
    kinds: tuple[DerKind, ...] = ("PV", "PV", "PV", "DFIG", "PV")
    ders = tuple(DER(b, kind, rating) for b, kind in zip(picks, kinds, strict=True))
    return _paper_limits(net.with_changes(name=name, ders=ders))


def feeder(copies: int, name: str | None = None) -> Network:
    """The large radial feeder of `copies` case33bw copies (rule: `opfbench.cases.feeder`);
    33·copies buses, named `feeder-<copies>x` unless `name` is given."""
    base = load_case_file(_matpower_file("case33bw"), "case33bw")
    return replicated_feeder(base, place_ders(base, "case33bw-der"), copies, name or f"feeder-{copies}x")


_BUILDERS: dict[str, Callable[[], Network]] = {
    "case33bw": lambda: load_case_file(_matpower_file("case33bw"), "case33bw"),
    "case69": lambda: load_case_file(_matpower_file("case69"), "case69"),
    "case141": lambda: load_case_file(_matpower_file("case141"), "case141"),
    "paper33": lambda: _paper33(meshed=False),
    "paper33-meshed": lambda: _paper33(meshed=True),
    "case69-der": lambda: place_ders(load_case_file(_matpower_file("case69")), "case69-der"),
    "case141-der": lambda: place_ders(load_case_file(_matpower_file("case141")), "case141-der"),
}
_BUILDERS |= {name: partial(feeder, copies, name) for name, copies in SHIPPED_COPIES.items()}

CASE_NAMES = tuple(_BUILDERS)


@lru_cache(maxsize=None)
def shipped_network(name: str) -> Network:
    """The shipped case `name` (one of `CASE_NAMES`), built once per process."""
    return _BUILDERS[name]()
