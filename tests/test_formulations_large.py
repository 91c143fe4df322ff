"""Large radial feeders: the formulations build and solve without dense n×n data.

`replicated_feeder(copies)` builds a radial feeder of 1 + 32·copies buses in memory:
`copies` copies of paper33's 32 non-slack buses (lines, loads, DERs), each hanging off
the one slack bus. Every copy is electrically paper33 (the slack holds the voltage),
so each copy's optimum is paper33's — a check that does not depend on the size.
"""

from __future__ import annotations

import tracemalloc

import casadi as ca
import numpy as np
import pytest

from opfbench.formulations.model import build_problem_model
from opfbench.formulations.opf_strategies import run_acopf
from opfbench.io import load_network
from opfbench.network import DER, Network
from opfbench.scenario import Scenario


def replicated_feeder(copies: int) -> Network:
    """paper33 with its non-slack part repeated `copies` times around the slack bus."""
    base = load_network("paper33")
    if base.slack != 0 or np.any(base.bus_type[1:] != 1):
        raise AssertionError("paper33 is expected to have the slack first and PQ buses elsewhere")
    m = base.n_bus - 1
    offset = np.repeat(np.arange(copies) * m, base.n_branch)

    def buses(a: np.ndarray) -> np.ndarray:  # bus arrays: slack once, the rest per copy
        return np.concatenate([a[:1], np.tile(a[1:], copies)])

    def ends(idx: np.ndarray) -> np.ndarray:  # branch end indices in the replicated numbering
        local = np.tile(idx, copies)
        return np.where(local == 0, 0, local + offset)

    ders = tuple(DER(d.bus + c * m, d.kind, d.rating_mw) for c in range(copies) for d in base.ders)
    return base.with_changes(
        name=f"paper33x{copies}",
        bus_ids=np.arange(1, 1 + 1 + copies * m),
        bus_type=buses(base.bus_type),
        base_kv=buses(base.base_kv),
        load_p_mw=buses(base.load_p_mw),
        load_q_mvar=buses(base.load_q_mvar),
        gs_mw=buses(base.gs_mw),
        bs_mvar=buses(base.bs_mvar),
        vmin=buses(base.vmin),
        vmax=buses(base.vmax),
        f=ends(base.f),
        t=ends(base.t),
        **{k: np.tile(getattr(base, k), copies) for k in ("r", "x", "b", "tap", "shift", "status")},
        ders=ders,
    )


def test_replicated_feeder_ac_opf_is_paper33s_per_copy():
    """Losses to 1e-6 relative; Q to 5e-5 MVAr (of 0.2 MVAr setpoints): the losses are
    flat in Q near the optimum, and the SOCP's and IPOPT's optima differ there by up to
    1.4e-5 MVAr within their tolerances."""
    copies = 3
    net = replicated_feeder(copies)
    assert net.n_bus == 1 + 32 * copies and not net.meshed and len(net.ders) == 5 * copies
    single = run_acopf(Scenario.snapshot(load_network("paper33"), 1.0, 0.8), 0.0, solver="ipopt")
    for solver in ("auto", "ipopt"):
        res = run_acopf(Scenario.snapshot(net, 1.0, 0.8), 0.0, solver=solver)
        assert res.status[0] == "ok"
        assert res.losses_kw[0] == pytest.approx(copies * single.losses_kw[0], rel=1e-6)
        np.testing.assert_allclose(res.q_mvar[0], np.tile(single.q_mvar[0], copies), atol=5e-5)


def test_models_are_sparse():
    """The NLP's constraint Jacobian and the SOCP's conic matrix have O(n) nonzeros, and
    the SOCP's offset map one entry per data value (no dense n×n anywhere)."""
    net = replicated_feeder(20)
    nlp = build_problem_model("exact", net).ipopt.nlp
    assert ca.jacobian(nlp["g"], nlp["x"]).nnz() < 16 * net.n_bus  # dense: 4·n²
    program = build_problem_model("relaxation", net).program
    assert program._a.nnz < 25 * net.n_bus
    assert program._b_theta.nnz <= 2 * net.n_bus + 2 * len(net.ders)
    # The bound screening's own data is linear in the bound rows too (a pairing by
    # broadcasting, 3·rows² bytes, took 5 GB on feeder10k): a few index arrays, at most
    # 64 bytes per row and per variable.
    tracemalloc.start()
    program._screening(program._dims)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 64 * (program._bounds.size + program.n_x) + 100_000, peak
