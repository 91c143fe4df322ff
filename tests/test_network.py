"""Network model: topology helpers, per-unit data, islanding."""

import numpy as np
import pytest

from opfbench.errors import NetworkError
from opfbench.io import load_network


def test_paper33_topology():
    net = load_network("paper33")
    ids = net.bus_ids
    parent_of = {int(ids[j]): int(ids[p]) for j, p in enumerate(net.parent) if p >= 0}
    assert parent_of[2] == 1 and parent_of[19] == 2 and parent_of[23] == 3 and parent_of[26] == 6
    assert not net.meshed
    leaves = set(ids[net.is_leaf].tolist())
    assert leaves == {18, 22, 25, 33}
    assert sorted(ids[list(net.children[net.index_of(2)])]) == [3, 19]
    assert [int(ids[d.bus]) for d in net.ders] == [10, 16, 19, 29, 27]
    assert net.der_kinds == ("PV", "PV", "PV", "PV", "DFIG")
    assert np.all(net.vmin == 0.9) and np.all(net.vmax == 1.1) and net.v_slack == 1.0


def test_meshed_variant_closes_the_five_ties():
    net = load_network("paper33-meshed")
    assert net.meshed and net.status.all() and net.n_branch == 37


def test_parent_branch_connects_parent():
    net = load_network("case69")
    for j in range(net.n_bus):
        k = net.parent_branch[j]
        if k >= 0:
            assert {net.f[k], net.t[k]} == {j, net.parent[j]}


def test_opening_a_line_islands_buses():
    net = load_network("case33bw")
    status = net.status.copy()
    status[net.parent_branch[net.index_of(30)]] = False  # line 29–30
    with pytest.raises(NetworkError, match=r"islanded .*30, 31, 32, 33"):
        net.with_changes(status=status)
