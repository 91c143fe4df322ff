"""The SOCP relaxation of a network and its solves on every snapshot, shared by data.

The model: DistFlow (`models.distflow`) on radial feeders, Jabr's bus injection
(`models.jabr`) on meshed ones; built once per network and option *per thread*
(`cache.per_thread`); `build_socp` builds a new one for callers who want their own.

`relaxed_solves(net, data, slack_export)` answers every snapshot of `data` from the
process's solve cache (`cache.SolveCache`, keyed on the network, the options and the
snapshot's data θ) and solves only what it does not hold, so every caller on the same
data — `run_socp`, and `run_acopf` for its bound, fast path and fallback, on whatever
Scenario objects they were given; the daytime steps of the three night modes — gets the
same solves. A solve is a function of its data alone (Clarabel setups updated in place;
bound screening answers with the snapshot's own active set whatever was solved before,
`solvers.clarabel_adapter`), so sharing changes no digit. One more exact share: the
paper's slack rule from the unrestricted problem. The problem with slack P ≥ 0 is the
unrestricted one with one more constraint, so where the unrestricted optimum already
imports (slack P ≥ 0) it is the restricted optimum too, and where the unrestricted
problem is infeasible so is the restricted one; only the other snapshots (the slack
exports at the unrestricted optimum, or its solve failed) are solved again.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from opfbench.formulations.cache import SolveCache, per_thread
from opfbench.formulations.models.distflow import DistFlowSocp
from opfbench.formulations.models.jabr import JabrSocp
from opfbench.formulations.models.soc import SocpRelaxation, SocpSolve, curtail_vector, data_vector
from opfbench.formulations.problem import CurtailData, PqCapability, SnapshotData, snapshot_data
from opfbench.network import Network
from opfbench.scenario import Scenario

CACHE_BYTES = 256 * 2**20  # the solve cache's size in this process (estimated)
SOLVE_BYTES = 200  # a SocpSolve without its q_pu array (estimate)


def model_of(net: Network) -> type[SocpRelaxation]:
    """The relaxation model of `net`: Jabr's on meshed feeders, DistFlow on radial ones."""
    return JabrSocp if net.meshed else DistFlowSocp


def build_socp(net: Network, slack_export: bool = True, curtail: PqCapability | None = None) -> SocpRelaxation:
    """A new relaxation of `net` (the caller's own: its Clarabel instance is mutable);
    `curtail`: the one that decides the DER's active power too, at that capability."""
    return model_of(net)(net, slack_export, curtail)


def relaxation(net: Network, slack_export: bool = True) -> SocpRelaxation:
    """The relaxation of `net`, built once per network and option in this thread."""
    return per_thread(net, ("socp", bool(slack_export)), lambda: build_socp(net, slack_export))


def _solve_bytes(solve: SocpSolve) -> int:
    return SOLVE_BYTES + (solve.q_pu.nbytes if solve.q_pu is not None else 0)


_cache: SolveCache[SocpSolve] = SolveCache(CACHE_BYTES, _solve_bytes)


def forget_solves() -> None:
    """Empty this process's solve cache (benchmarks timing the solves themselves)."""
    _cache.clear()


def _restricted(unrestricted: SocpSolve) -> SocpSolve | None:
    """The slack-may-not-export problem's solve where the unrestricted one settles it (see
    the module docstring), else None."""
    if unrestricted.infeasible or (unrestricted.optimal and unrestricted.slack_p_pu >= 0.0):
        return unrestricted
    return None


def relaxed_solves(
    net: Network, data: SnapshotData, slack_export: bool = True, skip: np.ndarray | None = None
) -> tuple[SocpSolve, ...]:
    """The relaxation of `net` solved on every snapshot of `data`, shared by data as the
    module docstring says; snapshots marked in `skip` (S,) bool are neither solved nor
    looked up (`SocpSolve.not_solved`), so a caller's result does not depend on what the
    cache holds."""
    if skip is not None and skip.any():
        keep = np.flatnonzero(~skip)
        part = iter(relaxed_solves(net, SnapshotData(data.s_fixed[keep], data.q_limit[keep]), slack_export) if keep.size else ())
        return tuple(SocpSolve.not_solved() if skipped else next(part) for skipped in skip)
    unrestricted = None if slack_export else relaxed_solves(net, data, True)
    thetas = data_vector(data.s_fixed, data.q_limit)
    found = _cache.get_many(_cache.keys(net, ("socp", bool(slack_export)), thetas))
    if unrestricted is not None:
        found = [_restricted(unrestricted[i]) if solve is None else solve for i, solve in enumerate(found)]
    return _solved(net, ("socp", bool(slack_export)), thetas, found, lambda: relaxation(net, slack_export))


def _solved(
    net: Network, options: tuple, thetas: np.ndarray, found: list[SocpSolve | None], model: Callable[[], SocpRelaxation]
) -> tuple[SocpSolve, ...]:
    """Every snapshot's solve: `found` (the cache's, None where it has none) and the others
    solved by `model()` — a snapshot whose data come again in the batch once —, all then
    cached under `options`."""
    keys = _cache.keys(net, options, thetas)
    first: dict[tuple, int] = {}  # a snapshot whose data come again in this batch is solved once
    for i, solve in enumerate(found):
        if solve is None:
            first.setdefault(keys[i], i)
    todo = sorted(first.values())
    solved = dict(zip(todo, model().solve_data(thetas[todo]) if todo else [], strict=True))
    solves = tuple(solve if solve is not None else solved[first[key]] for solve, key in zip(found, keys, strict=True))
    _cache.put_many(list(zip(keys, solves, strict=True)))
    return solves


def curtail_solves(net: Network, data: CurtailData, k: float, slack_export: bool = True) -> tuple[SocpSolve, ...]:
    """The relaxation that decides the DER's active power too (`models.soc`, `curtail`) solved
    on every snapshot of `data` at reserve k, shared by data as `relaxed_solves` is."""
    options = ("socp-curtail", bool(slack_export), float(k))
    thetas = curtail_vector(data.s_fixed, data.p_avail, data.p_low, data.offset)

    def model() -> SocpRelaxation:
        return per_thread(net, options, lambda: build_socp(net, slack_export, PqCapability.of(net, k)))

    return _solved(net, options, thetas, _cache.get_many(_cache.keys(net, options, thetas)), model)


def socp_solves(
    scenario: Scenario,
    k: float,
    slack_export: bool = True,
    data: SnapshotData | None = None,
    skip: np.ndarray | None = None,
) -> tuple[SocpSolve, ...]:
    """`relaxed_solves` on the snapshots of `scenario` with reserve k; `data`: the scenario's
    `snapshot_data(scenario, k)` when the caller has it; `skip`: snapshots not to solve."""
    return relaxed_solves(scenario.net, snapshot_data(scenario, k) if data is None else data, slack_export, skip)
