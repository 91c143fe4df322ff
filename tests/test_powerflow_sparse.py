"""Sparse kernels (SuperLU) against the dense ones: the same Newton–Raphson iterates and
the same batched solutions on every shipped small case, PV buses and taps included."""

import numpy as np
import pytest

from opfbench.io import load_network
from opfbench.io.matpower import load_case_file
from opfbench.powerflow import SPARSE_MIN_BUSES, bus_injections, solve_pf, solve_pf_batch, uses_sparse
from tests.support.matpower_texts import CASE4_PV


def _injections(net, n, seed):
    rng = np.random.default_rng(seed)
    n_der = len(net.ders)
    return bus_injections(
        net,
        rng.uniform(0, 1, (n, n_der)) * net.der_rating_mw,
        rng.uniform(-0.5, 0.5, (n, n_der)) * net.der_rating_mw,
        rng.uniform(0.2, 1.6, n),
    )


@pytest.mark.parametrize("name", ["paper33", "case69-der", "case141-der", "paper33-meshed"])
def test_sparse_newton_equals_dense(name):
    net = load_network(name)
    for row in _injections(net, 10, seed=11):
        dense, sparse = solve_pf(net, row, sparse=False), solve_pf(net, row, sparse=True)
        assert dense.converged and sparse.converged
        assert sparse.iterations == dense.iterations
        assert np.abs(sparse.v - dense.v).max() <= 1e-9


@pytest.mark.parametrize("name", ["paper33", "case69-der", "case141-der", "paper33-meshed"])
def test_sparse_batch_equals_dense_batch(name):
    net = load_network(name)
    s = _injections(net, 48, seed=5)
    dense, sparse = solve_pf_batch(net, s, sparse=False), solve_pf_batch(net, s, sparse=True)
    assert dense.converged.all() and sparse.converged.all()
    assert np.abs(sparse.v - dense.v).max() <= 1e-9
    assert np.abs(sparse.losses_kw - dense.losses_kw).max() <= 1e-6


def test_sparse_newton_with_pv_bus_and_tap(tmp_path):
    path = tmp_path / "case4pv.m"
    path.write_text(CASE4_PV)
    net = load_case_file(path)
    dense, sparse = solve_pf(net, bus_injections(net), sparse=False), solve_pf(net, bus_injections(net), sparse=True)
    assert sparse.converged and np.abs(sparse.v - dense.v).max() <= 1e-9
    assert sparse.vm[net.index_of(400)] == pytest.approx(1.05)
    batch = solve_pf_batch(net, np.array([bus_injections(net)] * 2), sparse=True)
    assert batch.converged.all() and np.abs(batch.v - dense.v).max() <= 1e-9


def test_sparse_reports_non_convergence():
    net = load_network("paper33")
    assert not solve_pf(net, bus_injections(net, 0.0, 0.0, 10.0), sparse=True).converged
    batch = solve_pf_batch(net, bus_injections(net, 0.0, 0.0, np.array([1.0, 10.0])), sparse=True)
    assert list(batch.converged) == [True, False]


def test_dense_below_the_threshold_sparse_from_it():
    assert not uses_sparse(load_network("case69")) and load_network("case69").n_bus < SPARSE_MIN_BUSES
    assert uses_sparse(load_network("case141")) and uses_sparse(load_network("feeder1k"))
