"""The solves of a relaxation or approximation (a `model.BatchModel`) on every snapshot,
shared by data.

`model_solves(model, net, data, slack_export)` answers every snapshot of `data` from the
process's solve cache (`cache.SolveCache`, keyed on the network, the model and its slack
rule, and the snapshot's data θ) and solves only what it does not hold, so every caller on
the same data — the `socp` strategy, and the AC OPF for its bound, fast path and fallback
(both ask for the OPF problem's relaxation: `relaxation_solves`), on whatever Scenario
objects they were given; the daytime steps of the three night modes — gets the same
solves. A solve is a function of its data alone (Clarabel setups updated in place; bound
screening answers with the snapshot's own active set whatever was solved before,
`solvers.clarabel_adapter`), so sharing changes no digit. The model is built once per
network and slack rule per thread (`model.built`). One more exact share: the slack rule
from the unrestricted problem. The problem with slack P ≥ 0 is the unrestricted one with
one more constraint, so where the unrestricted optimum already imports (slack P ≥ 0) it is
the restricted optimum too, and where the unrestricted problem is infeasible so is the
restricted one; only the other snapshots (the slack exports at the unrestricted optimum,
or its solve failed) are solved again.

`curtail_solves`: the OPF problem's relaxation that decides the DER's active power too
(`models.conic`, `curtail`), shared by data the same way, per reserve k (its capability is
compiled in).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from opfbench.formulations.model import BatchModel, built, model_for
from opfbench.formulations.models.conic import SnapshotSolve, curtail_vector, data_vector
from opfbench.formulations.problem import CurtailData, PqCapability, SnapshotData, snapshot_data
from opfbench.formulations.solver_cache import SolveCache, per_thread
from opfbench.network import Network
from opfbench.registry.specs import ModelSpec
from opfbench.scenario import Scenario
from opfbench.state import PROCESS

CACHE_BYTES = 256 * 2**20  # the solve cache's size in this process (estimated)
SOLVE_BYTES = 200  # a SnapshotSolve without its q_pu array (estimate)


def _solve_bytes(solve: SnapshotSolve) -> int:
    return SOLVE_BYTES + (solve.q_pu.nbytes if solve.q_pu is not None else 0)


_cache: SolveCache[SnapshotSolve] = SolveCache(CACHE_BYTES, _solve_bytes)


def forget_solves() -> None:
    """Empty this process's solve cache (benchmarks timing the solves themselves)."""
    _cache.clear()


PROCESS.on_reset("formulation solves", forget_solves)


def _restricted(unrestricted: SnapshotSolve) -> SnapshotSolve | None:
    """The slack-may-not-export problem's solve where the unrestricted one settles it (see
    the module docstring), else None."""
    if unrestricted.infeasible or (unrestricted.optimal and unrestricted.slack_p_pu >= 0.0):
        return unrestricted
    return None


def model_solves(
    model: ModelSpec, net: Network, data: SnapshotData, slack_export: bool = True, skip: np.ndarray | None = None
) -> tuple[SnapshotSolve, ...]:
    """`model` solved on every snapshot of `data`, shared by data as the module docstring
    says; snapshots marked in `skip` (S,) bool are neither solved nor looked up
    (`SnapshotSolve.not_solved`), so a caller's result does not depend on what the cache
    holds."""
    if skip is not None and skip.any():
        keep = np.flatnonzero(~skip)
        part = iter(
            model_solves(model, net, SnapshotData(data.s_fixed[keep], data.q_limit[keep]), slack_export) if keep.size else ()
        )
        return tuple(SnapshotSolve.not_solved() if skipped else next(part) for skipped in skip)
    unrestricted = None if slack_export else model_solves(model, net, data, True)
    thetas = data_vector(data.s_fixed, data.q_limit)
    options = (model.name, bool(slack_export))
    found = _cache.get_many(_cache.keys(net, options, thetas))
    if unrestricted is not None:
        found = [_restricted(unrestricted[i]) if solve is None else solve for i, solve in enumerate(found)]
    return _solved(net, options, thetas, found, lambda: built(model, net, slack_export))


def _solved(
    net: Network, options: tuple, thetas: np.ndarray, found: list[SnapshotSolve | None], model: Callable[[], BatchModel]
) -> tuple[SnapshotSolve, ...]:
    """Every snapshot's solve: `found` (the cache's, None where it has none) and the others
    solved by `model()` (built on first need only) — a snapshot whose data come again in
    the batch once —, all then cached under `options`."""
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


def curtail_solves(net: Network, data: CurtailData, k: float, slack_export: bool = True) -> tuple[SnapshotSolve, ...]:
    """The OPF problem's relaxation that decides the DER's active power too, solved on every
    snapshot of `data` at reserve k, shared by data as `model_solves` is."""
    spec = model_for("relaxation", net)
    options = (f"{spec.name}-curtail", bool(slack_export), float(k))
    thetas = curtail_vector(data.s_fixed, data.p_avail, data.p_low, data.offset)

    def model() -> BatchModel:
        build: Callable[..., BatchModel] = spec.build  # a conic model: it takes the capability to curtail
        return per_thread(net, options, lambda: build(net, slack_export, PqCapability.of(net, k)))

    return _solved(net, options, thetas, _cache.get_many(_cache.keys(net, options, thetas)), model)


def relaxation_solves(
    scenario: Scenario,
    k: float,
    slack_export: bool = True,
    data: SnapshotData | None = None,
    skip: np.ndarray | None = None,
) -> tuple[SnapshotSolve, ...]:
    """The OPF problem's relaxation (`model.model_for`) on the snapshots of `scenario` with
    reserve k (`model_solves`); `data`: the scenario's `snapshot_data(scenario, k)` when
    the caller has it; `skip`: snapshots not to solve."""
    net = scenario.net
    data = snapshot_data(scenario, k) if data is None else data
    return model_solves(model_for("relaxation", net), net, data, slack_export, skip)
