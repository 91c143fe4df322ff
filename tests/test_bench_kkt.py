"""`bench.kkt`, where the physical limit of a relaxation answer lies: its LDLᵀ (the peer
of Clarabel's iterations) solves the KKT system, its nonzeros are QDLDL's, the flop count
is George & Liu's, and the figures of a real relaxation hang together."""

import numpy as np
import pytest
import scipy.sparse as sp

from opfbench.bench.kkt import Ldl, factor_flops, kkt_figures, kkt_pattern
from opfbench.bench.opf import daily_scenario
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.models.conic import data_vector
from opfbench.formulations.problem import snapshot_data
from opfbench.io import load_network


@pytest.fixture(scope="module")
def relaxation():
    net = load_network("paper33")
    model = build_problem_model("relaxation", net)
    scenario = daily_scenario(net, 4)
    data = snapshot_data(scenario, 0.0)
    return model.program, model.program.offsets(data_vector(data.s_fixed, data.q_limit))


def test_the_ldl_solves_the_kkt_system_under_qdldls_ordering(relaxation):
    import qdldl

    program, _ = relaxation
    k = kkt_pattern(program)
    assert (abs(k - k.T) > 0).nnz == 0  # symmetric
    lower, d, perm = qdldl.Solver(k).factors()
    ldl = Ldl(k, np.asarray(perm))
    ldl.factor()
    assert ldl.lnz.sum() == sp.csc_matrix(lower).nnz  # the same pattern as QDLDL's own
    np.testing.assert_allclose(ldl.d, d, rtol=1e-12)
    n = program.n_x
    assert (ldl.d[np.argsort(perm)][:n] > 0).all() and (ldl.d[np.argsort(perm)][n:] < 0).all()  # quasidefinite
    rhs = np.random.default_rng(1).normal(size=k.shape[0])
    x = np.empty_like(rhs)
    x[perm] = ldl.solve(rhs[perm])
    np.testing.assert_allclose(k @ x, rhs, atol=1e-9)


def test_the_flop_count_of_a_dense_factor():
    # a dense n×n Cholesky factor: c_j = n − 1 − j below the diagonal; Σ c(c+3) = n³/3 + O(n²)
    n = 60
    counts = np.arange(n - 1, -1, -1)
    assert factor_flops(counts) == sum(c * (c + 3) for c in range(n))
    assert abs(factor_flops(counts) / (n**3 / 3) - 1) < 0.1


def test_the_figures_of_a_real_relaxation(relaxation):
    program, offsets = relaxation
    f = kkt_figures(program, offsets, repeats=3)
    assert f["variables"] == program.n_x and f["kkt_dim"] == f["variables"] + f["rows"]
    assert f["soc_cones"] == 32  # paper33's 32 branches
    assert f["fill"] >= 1.0 and f["ldl_nnz"] >= f["kkt_nnz"] - f["kkt_dim"]
    assert f["iteration_kflop"] > f["factor_kflop"] > 0
    assert f["iterations_median"] >= 3 and f["iteration_us"] > 0 and f["ldl_us"] > 0
    assert f["iteration_over_ldl"] == f["iteration_us"] / f["ldl_us"]
