"""AC power flow: published case figures, pandapower as oracle, batched vs single."""

import numpy as np
import pytest

from opfbench.errors import InputError
from opfbench.io import load_network
from opfbench.powerflow import PowerFlowResult, bus_injections, solve_pf, solve_pf_batch
from tests.support.matpower_texts import CASE4_PV


def _pf(name, der_mw=0.0, load_scale=1.0):
    net = load_network(name)
    return solve_pf(net, bus_injections(net, der_mw, 0.0, load_scale))


@pytest.mark.parametrize(
    "name, losses_kw, vmin, vmin_bus",
    [
        ("case33bw", 202.68, 0.9131, 18),  # Baran & Wu, as MATPOWER reports it
        ("case69", 224.99, 0.9092, 65),
    ],
)
def test_published_figures(name, losses_kw, vmin, vmin_bus):
    r = _pf(name)
    assert r.converged
    assert r.losses_kw == pytest.approx(losses_kw, abs=0.05)
    v, bus = r.extreme_voltage("min")
    assert v == pytest.approx(vmin, abs=5e-4) and bus == vmin_bus


def test_paper33_nominal_with_der_at_0_8():
    r = _pf("paper33", der_mw=0.48)
    assert r.converged
    assert r.losses_kw == pytest.approx(84.26, abs=0.05)
    assert r.extreme_voltage("min")[1] == 33


def test_losses_equal_power_balance():
    net = load_network("paper33")
    r = solve_pf(net, bus_injections(net, 0.3, 0.1, 1.1))
    balance = r.slack_s_mva.real + net.der_rating_mw.size * 0.3 - 1.1 * net.load_p_mw.sum()
    assert r.losses_kw == pytest.approx(balance * 1e3, abs=1e-4)  # NR tolerance 1e-9 p.u. on 10 MVA


def test_heavy_load_reports_non_convergence():
    r = _pf("paper33", load_scale=10.0)
    assert not r.converged
    batch = solve_pf_batch(load_network("paper33"), bus_injections(load_network("paper33"), 0.0, 0.0, np.array([1.0, 10.0])))
    assert list(batch.converged) == [True, False]


def test_a_singular_jacobian_ends_newton_without_a_step():
    from opfbench.powerflow.dense import DenseNewton

    newton = DenseNewton(load_network("paper33"))
    newton.y_rows = np.zeros_like(newton.y_rows)  # no branch: every derivative is 0
    newton.y_sub_conj = np.zeros_like(newton.y_sub_conj)
    v = np.ones(newton.y_rows.shape[1], dtype=complex)
    assert newton.step(v, np.ones(2 * len(newton.pvpq) - len(newton.pv))) is None


def test_nan_injection_is_a_clear_error():
    net = load_network("paper33")
    with pytest.raises(InputError, match="NaN"):
        bus_injections(net, np.array([0.1, np.nan, 0.1, 0.1, 0.1]))


def _random_points(name, n, seed):
    net = load_network(name)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield (
            net,
            rng.uniform(0.2, 1.6),
            rng.uniform(0, 1, len(net.ders)) * net.der_rating_mw,
            rng.uniform(-0.5, 0.5, len(net.ders)) * net.der_rating_mw,
        )


@pytest.mark.parametrize("name", ["paper33", "case69-der"])
def test_agrees_with_pandapower(name):
    from tests.support.pandapower_oracle import pandapower_pf

    points = list(_random_points(name, 20, seed=7))
    for net, ls, p, q in points:
        ours = solve_pf(net, bus_injections(net, p, q, ls))
        vm, losses, _ = pandapower_pf(net, ls, p, q)
        assert ours.converged
        assert np.max(np.abs(ours.vm - vm)) < 1e-6
        assert abs(ours.losses_kw - losses) < 1e-3


@pytest.mark.parametrize("name", ["paper33", "case69-der", "paper33-meshed", "case141-der"])
def test_batched_agrees_with_single(name):
    points = list(_random_points(name, 40, seed=3))
    net = points[0][0]
    s = np.array([bus_injections(net, p, q, ls) for _, ls, p, q in points])
    batch = solve_pf_batch(net, s)
    assert batch.converged.all()
    for k, row in enumerate(s):
        single = solve_pf(net, row)
        assert np.max(np.abs(batch.v[k] - single.v)) < 1e-9
        assert abs(batch.losses_kw[k] - single.losses_kw) < 1e-5  # NR stops at 1e-9 p.u. = 1e-5 kW


def test_batched_warm_start_converges_to_the_same_point_in_fewer_iterations():
    net = load_network("paper33")
    s = bus_injections(net, np.array([[0.3] * 5, [0.5] * 5]), np.array([[0.1] * 5, [-0.1] * 5]), np.array([1.0, 0.8]))
    cold = solve_pf_batch(net, s)
    near = bus_injections(net, np.array([[0.31] * 5, [0.5] * 5]), np.array([[0.1] * 5, [-0.1] * 5]), np.array([1.0, 0.8]))
    start = cold.v.copy()
    start[1] = np.nan  # an unusable start row falls back to the no-load start
    warm = solve_pf_batch(net, near, v0=start)
    reference = solve_pf_batch(net, near)
    assert warm.converged.all()
    assert np.abs(warm.v - reference.v).max() < 1e-9
    assert warm.iterations[0] < reference.iterations[0] and warm.iterations[1] == reference.iterations[1]


def test_case_with_pv_bus_and_tap_matches_pandapower(tmp_path):
    """A meshed-free 4-bus case with a voltage-controlled bus and an off-nominal tap."""
    from opfbench.io.matpower import load_case_file
    from tests.support.pandapower_oracle import pandapower_pf

    path = tmp_path / "case4pv.m"
    path.write_text(CASE4_PV)
    net = load_case_file(path)
    ours = solve_pf(net, bus_injections(net))
    vm, losses, _ = pandapower_pf(net, 1.0, np.zeros(0), np.zeros(0))
    assert ours.converged
    assert np.max(np.abs(ours.vm - vm)) < 1e-6
    assert abs(ours.losses_kw - losses) < 1e-3
    assert ours.vm[net.index_of(400)] == pytest.approx(1.05)
    assert solve_pf_batch(net, np.array([bus_injections(net)] * 2)).converged.all()


def test_a_batched_flow_asked_again_is_answered_from_the_memo(paper33, monkeypatch):
    """The same injections on the same network are not solved again and give the same
    figures bit for bit (arrays of their own: changing them changes no later answer); an
    input differing in one value is solved in that snapshot only; another network object or
    a warm start is solved anew."""
    import opfbench.powerflow as pf
    from opfbench.powerflow.memo import forget_flows

    solved: list[int] = []
    batch = pf._batch
    monkeypatch.setattr(pf, "_batch", lambda net, s, *rest: solved.append(len(s)) or batch(net, s, *rest))
    rng = np.random.default_rng(4)
    s = np.stack([bus_injections(paper33, load_scale=x) for x in rng.uniform(0.3, 1.2, 6)])
    forget_flows()
    first = solve_pf_batch(paper33, s)
    expected = first.v.copy()
    first.v[:] = 0
    again = solve_pf_batch(paper33, s.copy())
    assert solved == [6]
    np.testing.assert_array_equal(again.v, expected)
    np.testing.assert_array_equal(again.iterations, first.iterations)
    changed = s.copy()
    changed[3, 5] += 1e-12
    other = solve_pf_batch(paper33, changed)
    assert solved == [6, 1] and not np.array_equal(other.v[3], expected[3])
    np.testing.assert_array_equal(other.v[[0, 1, 2, 4, 5]], expected[[0, 1, 2, 4, 5]])
    twin = load_network("paper33-meshed")  # another network object: never its answer
    solve_pf_batch(twin, s)
    solve_pf_batch(paper33, s, v0=expected)
    assert solved == [6, 1, 6, 6]
    forget_flows()  # a fresh solve gives the same figures bit for bit
    np.testing.assert_array_equal(solve_pf_batch(paper33, s).v, expected)
    assert solved == [6, 1, 6, 6, 6]


def test_a_snapshot_solved_before_is_answered_from_the_row_memo(paper33, monkeypatch):
    """Warm or cold, only the snapshots this thread has not solved from the same injections
    and start are solved (each distinct one once); the others' answers are those of a
    fresh solve bit for bit; a changed start, or a warm start where a cold one was solved,
    is a new snapshot."""
    import opfbench.powerflow as pf
    from opfbench.powerflow.memo import forget_flows

    solved: list[int] = []
    batch = pf._batch
    monkeypatch.setattr(pf, "_batch", lambda net, s, *rest: solved.append(len(s)) or batch(net, s, *rest))
    s = np.array([bus_injections(paper33, p, q, ls) for _, ls, p, q in _random_points("paper33", 8, seed=3)])
    start = solve_pf_batch(paper33, s).v * 1.001
    forget_flows()
    solved.clear()
    solve_pf_batch(paper33, s[:5], v0=start[:5])
    mixed = [4, 6, 0, 6, 7, 2]  # three known, 6 twice, 7 new
    got = solve_pf_batch(paper33, s[mixed], v0=start[mixed])
    assert solved == [5, 2]
    forget_flows()
    fresh = solve_pf_batch(paper33, s[mixed], v0=start[mixed])
    np.testing.assert_array_equal(got.v, fresh.v)
    np.testing.assert_array_equal(got.iterations, fresh.iterations)
    np.testing.assert_array_equal(got.converged, fresh.converged)
    solved.clear()
    other = start[:2].copy()
    other[1, 3] *= 1 + 1e-15  # one value of one start moved by an ulp
    solve_pf_batch(paper33, s[:2], v0=other)
    solve_pf_batch(paper33, s[:2])  # cold, where warm ones were solved
    assert solved == [1, 2]


def test_snapshots_whose_digests_collide_are_each_solved(paper33, monkeypatch):
    """A digest is only where a snapshot is looked for: with every snapshot given the same
    digest, a different snapshot — in a later call or the same batch, a warm start where a
    cold one was solved — is solved, never served another's answer; the same snapshot again
    is still not solved twice."""
    import opfbench.powerflow as pf
    from opfbench.powerflow.memo import forget_flows

    s = np.array([bus_injections(paper33, p, q, ls) for _, ls, p, q in _random_points("paper33", 4, seed=13)])
    start = solve_pf_batch(paper33, s).v * 1.001
    fresh = [solve_pf_batch(paper33, s[i : i + 1]) for i in range(4)]
    warm = solve_pf_batch(paper33, s[:1], v0=start[:1])
    assert warm.iterations[0] != fresh[0].iterations[0]  # the start shows in the answer
    solved: list[int] = []
    batch = pf._batch
    monkeypatch.setattr(pf, "_batch", lambda net, s, *rest: solved.append(len(s)) or batch(net, s, *rest))
    monkeypatch.setattr(pf, "row_digests", lambda s, v0: np.zeros(len(s), dtype=np.uint64))
    forget_flows()
    got = [solve_pf_batch(paper33, s[:1]), solve_pf_batch(paper33, s[1:2]), solve_pf_batch(paper33, s[[2, 3, 2]])]
    got_warm = solve_pf_batch(paper33, s[:1], v0=start[:1])
    assert solved == [1, 1, 2, 1]  # each snapshot solved once: row 2 twice in a batch is one
    for i, (g, row) in enumerate([(0, 0), (1, 0), (2, 0), (2, 1), (2, 2)]):
        want = fresh[[0, 1, 2, 3, 2][i]]
        np.testing.assert_array_equal(got[g].v[row], want.v[0])
        assert got[g].iterations[row] == want.iterations[0]
    np.testing.assert_array_equal(got_warm.v, warm.v)
    np.testing.assert_array_equal(got_warm.iterations, warm.iterations)


def test_the_memo_keeps_at_most_its_limit():
    """Batches of answers beyond the memo's limit are dropped oldest first (their snapshots
    are solved again); a snapshot answered again by a newer batch keeps the newer answer."""
    from opfbench.powerflow.memo import FlowMemo, row_digests

    net = load_network("paper33")
    s = np.array([bus_injections(net, p, q, ls) for _, ls, p, q in _random_points("paper33", 6, seed=7)]) / net.base_mva
    answers = solve_pf_batch(net, s * net.base_mva)
    keys = row_digests(s, None)
    assert len(set(keys.tolist())) == 6 and not (row_digests(s, s) == keys).any()  # a warm start is part of the snapshot
    memo = FlowMemo(limit_bytes=4 * (answers.v[0].nbytes + s[0].nbytes + 160))  # four single cold snapshots
    for rows in ([0], [1], [2], [3], [1], [4]):
        part = PowerFlowResult(net, answers.v[rows], answers.converged[rows], answers.iterations[rows])
        memo.put(net, "o", keys[rows], s[rows], None, part)
    assert memo.used <= memo.limit
    known, v, converged, iterations = memo.find(net, "o", keys, s, None)
    assert known.tolist() == [
        False,
        True,
        True,
        True,
        True,
        False,
    ]  # 0 went with the oldest batch (1's first with the next); 5 never came
    np.testing.assert_array_equal(v[1:5], answers.v[1:5])
    np.testing.assert_array_equal(iterations[1:5], answers.iterations[1:5])
    assert not memo.find(net, "other options", keys, s, None)[0].any()
    assert not memo.find(net, "o", keys, s, s)[0].any()  # the same digests, but not the same snapshots
    twin = load_network("paper33-meshed")  # another network: its table goes with its last batch
    memo.put(
        twin, "o", keys[:1], s[:1], None, PowerFlowResult(twin, answers.v[:1], answers.converged[:1], answers.iterations[:1])
    )
    for i in range(4):
        part = PowerFlowResult(net, answers.v[i : i + 1], answers.converged[:1], answers.iterations[:1])
        memo.put(net, "o", keys[i : i + 1], s[i : i + 1], None, part)
    assert (twin, "o") not in memo._tables and not memo.find(twin, "o", keys[:1], s[:1], None)[0].any()


def test_the_memos_table_finds_what_it_keeps_as_it_grows_and_drops():
    """The compiled table behind the memo, on digests crowded into few slots (equal low
    bits: long probe chains): every kept snapshot is found with its own answer, whatever
    the table's rebuilds as it grows; a dropped batch's are not, though their stale entries
    stay until a rebuild; a digest entered again takes its newer row; `first_rows` gives
    each digest's first row."""
    from opfbench.powerflow.memo import FlowMemo, first_rows

    net = load_network("paper33")
    rng = np.random.default_rng(9)
    n = 600
    digests = (rng.permutation(n).astype(np.uint64) << np.uint64(40)) | np.uint64(7)  # one slot wanted by all
    s = rng.standard_normal((n, 4)) + 1j * rng.standard_normal((n, 4))
    v = s * 2
    answer = PowerFlowResult(net, v, np.ones(n, dtype=bool), np.arange(n))
    row = v[0].nbytes + s[0].nbytes + 160  # one snapshot's bytes: voltages, injections, overhead
    memo = FlowMemo(limit_bytes=4 * 40 * row)  # 160 snapshots: four batches of 40
    for start in range(0, 560, 40):  # fourteen batches: all but the last four dropped
        part = slice(start, start + 40)
        memo.put(
            net,
            "o",
            digests[part],
            s[part].copy(),
            None,
            PowerFlowResult(net, v[part], answer.converged[part], answer.iterations[part]),
        )
    known, got, _, iterations = memo.find(net, "o", digests, s, None)
    assert known.tolist() == [False] * 400 + [True] * 160 + [False] * 40
    np.testing.assert_array_equal(got[400:560], v[400:560])
    np.testing.assert_array_equal(iterations[400:560], np.arange(400, 560))
    assert memo._tables[(net, "o")].filled == 6 * 40  # rebuilt (growing) without the stale entries of eight batches
    again = digests[[450, 580]]  # 450 answered anew (another snapshot that shares its digest), 580 new
    memo.put(
        net,
        "o",
        again,
        s[[0, 580]].copy(),
        None,
        PowerFlowResult(net, v[[0, 580]], answer.converged[:2], answer.iterations[[0, 580]]),
    )
    known, got, _, iterations = memo.find(net, "o", again, s[[450, 580]], None)
    assert known.tolist() == [False, True] and iterations[1] == 580
    known, _, _, iterations = memo.find(net, "o", again[:1], s[[0]], None)
    assert known.tolist() == [True] and iterations[0] == 0
    repeated = digests[rng.integers(0, 20, 500)]
    expected = [repeated.tolist().index(d) for d in repeated.tolist()]
    assert first_rows(repeated).tolist() == expected


@pytest.mark.parametrize("name, sparse", [("paper33", False), ("case69-der", False), ("case141-der", True), ("paper33", True)])
def test_each_snapshot_answer_is_its_own_whatever_else_is_in_the_batch(name, sparse):
    """A snapshot's voltages and iteration count are the same bit for bit solved alone, in
    any subset of the batch, at any position, cold or warm — what lets one flow answer
    several configurations (the dense mat-mul's columns are padded, `fixed_point.PAD`)."""
    from opfbench.powerflow.memo import forget_flows

    points = list(_random_points(name, 23, seed=11))
    net = points[0][0]
    s = np.array([bus_injections(net, p, q, ls) for _, ls, p, q in points])
    full = solve_pf_batch(net, s, sparse=sparse)
    rng = np.random.default_rng(5)
    start = full.v * (1 + 1e-3 * rng.standard_normal(full.v.shape))
    warm = solve_pf_batch(net, s, v0=start, sparse=sparse)
    for size in (1, 3, 5, 9, 17):
        rows = rng.permutation(len(s))[:size]
        forget_flows()
        part = solve_pf_batch(net, s[rows], sparse=sparse)
        np.testing.assert_array_equal(part.v, full.v[rows])
        np.testing.assert_array_equal(part.iterations, full.iterations[rows])
        np.testing.assert_array_equal(solve_pf_batch(net, s[rows], v0=start[rows], sparse=sparse).v, warm.v[rows])


def test_the_compiled_fixed_point_is_the_numpy_iteration_bit_for_bit(paper33):
    """The fused passes of `fixed_point` compute what the plain numpy iteration
    V ← Z·(conj(S)·V·(1/|V|²)) + V₀ computes, every snapshot stopping at its own step
    (on a multiple of PAD snapshots, where numpy's mat-mul has no edge columns)."""
    from opfbench.powerflow import SWEEP_TOLERANCE, _zbus
    from opfbench.powerflow.fixed_point import PAD

    rng = np.random.default_rng(2)
    n = 4 * PAD
    s = np.array(
        [bus_injections(paper33, rng.uniform(0, 1, 5) * paper33.der_rating_mw, 0.0, x) for x in rng.uniform(0.2, 1.5, n)]
    )
    fac = _zbus(paper33, False)
    s_conj = np.conj(s[:, fac.keep] / paper33.base_mva).T
    v = np.repeat(fac.v_noload[:, None], n, axis=1)
    expected, steps = np.empty_like(v), np.zeros(n, dtype=int)
    going = np.ones(n, dtype=bool)
    while going.any():
        mag2 = np.square(v.real) + np.square(v.imag)
        new = fac.z.z @ (s_conj * v * np.reciprocal(mag2)) + fac.v_noload[:, None]
        change = new - v
        step2 = (np.square(change.real) + np.square(change.imag)).max(axis=0)
        v = np.where(going, new, v)
        steps += going
        stop = going & (step2 < SWEEP_TOLERANCE**2)
        expected[:, stop] = v[:, stop]
        going &= ~stop
    result = solve_pf_batch(paper33, s)
    np.testing.assert_array_equal(result.v[:, fac.keep], expected.T)
    np.testing.assert_array_equal(result.iterations, steps)
