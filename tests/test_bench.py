"""The benchmark modules: JSON keys, a null for a peer that is not installed (JSON
contract), and the correctness figures they carry — batched vs single solutions, the
peers' voltages against ours, LFMA batched vs one snapshot at a time."""

import builtins

import numpy as np
import pandas as pd
import pytest

import opfbench.bench.local as bench_local
import opfbench.bench.opf as bench_opf
import opfbench.bench.pf as bench_pf
from opfbench.bench.paper_day import paper_day_scenario
from opfbench.bench.pf_large import measure, scaling
from opfbench.errors import InputError, NetworkError
from opfbench.io import load_network
from opfbench.io.matpower import load_case_file
from opfbench.powerflow import bus_injections, solve_pf
from opfbench.registry.catalog import specs
from tests.support.matpower_texts import CASE4_PV

PF_KEYS = {
    "case",
    "snapshots",
    "single_ms",
    "batch_1440_ms",
    "batch_converged",
    "batch_max_iterations",
    "batch_vs_single_max_dv_pu",
    "pandapower_loop_1440_ms",
    "pandapower_loop_snapshots",
    "ratio_vs_pandapower",
    "pandapower_max_dv_pu",
    "pandapower_numba",
    "pgm_batch_1440_ms",
    "ratio_vs_pgm",
    "pgm_max_dv_pu",
}


@pytest.fixture
def no_peers(monkeypatch):
    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name.split(".")[0] in ("pandapower", "power_grid_model"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)


def test_pf_bench_without_peers(no_peers, capsys):
    f = bench_pf.run()
    assert set(f) == PF_KEYS
    for key in (
        "pandapower_loop_1440_ms",
        "pandapower_loop_snapshots",
        "ratio_vs_pandapower",
        "pgm_batch_1440_ms",
        "ratio_vs_pgm",
    ):
        assert f[key] is None
    assert f["single_ms"] > 0 and f["batch_1440_ms"] > 0 and f["batch_converged"] == 1440
    assert f["batch_vs_single_max_dv_pu"] < 1e-9
    bench_pf.print_table(f)
    assert "not installed" in capsys.readouterr().out


def test_pf_peers_agree_with_us_on_the_paper_day(monkeypatch):
    monkeypatch.setattr(bench_pf, "NUMBA", False)  # numba's first-call compilation takes a minute
    day = paper_day_scenario("paper33")
    s = day.injections(0.0)[::60]
    assert bench_pf._pandapower_loop_ms(day.net, s, every=1)[1] < 1e-6
    assert bench_pf._pandapower_loop_ms(day.net, s, every=12)[1] < 1e-6  # the sample of the benchmark, scaled
    assert bench_pf._pgm_batch_ms(day.net, s)[1] < 1e-6


def test_pandapower_builder_keeps_taps_and_fixed_generators(tmp_path):
    """The one builder (to_ppc) on a case with an off-nominal tap and a PV generator."""
    import pandapower as pp

    path = tmp_path / "case4pv.m"
    path.write_text(CASE4_PV)
    net = load_case_file(path)
    s = bus_injections(net, load_scale=0.7)
    pnet = bench_pf.pandapower_net(net)
    bench_pf.set_injections(pnet, net, s)
    pp.runpp(pnet, tolerance_mva=1e-10, init="flat")
    assert np.abs(pnet.res_bus.vm_pu.to_numpy() - solve_pf(net, s).vm).max() < 1e-6
    with pytest.raises(NetworkError, match="plain series lines"):
        bench_pf._pgm_batch_ms(net, s[None, :])


def test_local_bench_batched_equals_one_by_one():
    day = paper_day_scenario("paper33").take(slice(0, 1440, 60))
    f = bench_local.bench_local(day, repeats=1, loop_sample=4)
    assert set(f["rules"]) == {s.name for s in specs() if s.kind == "local" and s.source == "opfbench" and not s.learned}
    assert all(r["ok"] == day.n_snapshots for r in f["rules"].values())
    assert f["rules"]["lfma"]["power_flows_per_snapshot"] == 4
    assert f["voltvar_day_ms"] == f["rules"]["volt-var"]["wall_ms"] > 0
    assert 1 < f["voltvar_iterations_mean"] <= f["rules"]["volt-var"]["power_flows_per_snapshot"]
    assert f["lfma_one_by_one_max_dq_mvar"] < 1e-9
    assert f["rules"]["lfma"]["energy_losses_kwh"] <= f["rules"]["no-action"]["energy_losses_kwh"]


def test_large_measurement_runs_in_its_own_process():
    r = measure("pf", "feeder1k")
    assert r["error"] is None and r["ok"]
    assert 0 < r["s"] <= r["first_s"] and r["mb"] >= r["baseline_mb"] > 0


def test_scaling_fits_exponents():
    rows, exponents = scaling(("paper33", "case141-der"))
    assert [r["buses"] for r in rows.values()] == [33, 141]
    assert set(exponents) == {"pf_s", "batch96_s", "lfma96_s"}
    assert all(np.isfinite(e) for e in exponents.values())


def test_opf_bench_without_peer(no_peers, capsys):
    f = bench_opf.bench_opf(n=6)
    assert f["pandapower_runopp_ms"] is None and f["ratio_ipopt_vs_pandapower"] is None
    assert f["solved"] == f["total"] == 6 and f["ipopt_ms"] > 0 and f["socp_ms"] > 0
    bench_opf.print_table(f)
    assert "pandapower not installed" in capsys.readouterr().out


def test_opf_bench_agrees_with_pandapower_runopp():
    """pandapower's OPF (PIPS) as the independent optimum: the same losses on every
    snapshot, its slack held at its setpoint as ours is (left free, runopp raises it to the
    bus's Vmax and reports up to 27 kW less on paper33)."""
    f = bench_opf.bench_opf(n=6, peer_every=1)
    assert f["pandapower_snapshots"] == 6
    assert f["pandapower_failures"] == 0 and f["pandapower_agrees"] == 6, f["pandapower_max_loss_diff_kw"]
    assert f["pandapower_max_loss_diff_kw"] <= bench_opf.AGREEMENT_KW


def test_load_case_names_the_large_feeders():
    assert load_network("feeder1k").n_bus == 990


def test_the_suite_year_against_a_reference_names_what_changed(tmp_path):
    """`bench run --suite --year --reference DIR`: certified shares and not-settled counts
    compared per configuration (NaN = NaN), energies by their largest relative change."""
    from opfbench.bench.run import compare_runs

    summary = pd.DataFrame(
        {
            "case": ["g", "g", "g"],
            "strategy": ["acopf", "lfma", "volt-var"],
            "k": [0.0, 0.0, 0.4],
            "night_mode": ["connected"] * 3,
            "forecast": ["off"] * 3,
            "energy_kwh": [10.0, 12.0, 11.0],
            "certified_share": [1.0, np.nan, np.nan],
            "not_settled_steps": [0, 0, 3],
        }
    )
    for name in ("ref", "same", "changed", "other"):
        (tmp_path / name).mkdir()
    summary.to_csv(tmp_path / "ref" / "summary.csv", index=False)
    summary.to_csv(tmp_path / "same" / "summary.csv", index=False)
    same = compare_runs(tmp_path / "same", tmp_path / "ref")
    assert same["certified_share_differs"] == [] and same["not_settled_differs"] == [] and same["identical_energies"]
    changed = summary.assign(energy_kwh=[10.0, 12.0 * (1 + 1e-9), 11.0], not_settled_steps=[0, 0, 4])
    changed.loc[0, "certified_share"] = 0.99
    changed.to_csv(tmp_path / "changed" / "summary.csv", index=False)
    diff = compare_runs(tmp_path / "changed", tmp_path / "ref")
    assert diff["certified_share_differs"] == ["g/acopf/0.0/connected/off"]
    assert diff["not_settled_differs"] == ["g/volt-var/0.4/connected/off"]
    assert diff["energy_max_rel_diff"] == pytest.approx(1e-9) and not diff["identical_energies"]
    summary.iloc[:2].to_csv(tmp_path / "other" / "summary.csv", index=False)
    with pytest.raises(InputError, match="not a run of the same grid"):
        compare_runs(tmp_path / "other", tmp_path / "ref")


def test_the_suite_year_against_a_stopped_reference_compares_its_finished_tasks(tmp_path):
    """A reference run stopped before its summary: the tasks it finished, each against the
    run's task of the same id — certified and not-settled counts per configuration."""
    from opfbench.bench.run import compare_runs

    part = pd.DataFrame(
        {
            "case": ["g", "g"],
            "strategy": ["acopf", "volt-var"],
            "k": [0.0, 0.0],
            "night_mode": ["connected"] * 2,
            "forecast": ["off"] * 2,
            "energy_kwh": [10.0, 11.0],
            "certified": [96, 0],
            "not_settled_steps": [0, 2],
        }
    )
    for name in ("ref", "run", "empty"):
        (tmp_path / name / "tasks").mkdir(parents=True)
    part.to_parquet(tmp_path / "ref" / "tasks" / "t1.summary.parquet")  # t2 never finished in the reference
    part.to_parquet(tmp_path / "run" / "tasks" / "t1.summary.parquet")
    part.assign(certified=[95, 0]).to_parquet(tmp_path / "run" / "tasks" / "t2.summary.parquet")
    same = compare_runs(tmp_path / "run", tmp_path / "ref")
    assert (same["tasks_compared"], same["reference_tasks"], same["configurations"]) == (1, 1, 2)
    assert same["certified_share_differs"] == [] and same["not_settled_differs"] == [] and same["identical_energies"]
    part.assign(certified=[95, 0], not_settled_steps=[0, 3]).to_parquet(tmp_path / "run" / "tasks" / "t1.summary.parquet")
    diff = compare_runs(tmp_path / "run", tmp_path / "ref")
    assert diff["certified_share_differs"] == ["t1/g/acopf/0.0/connected/off"]
    assert diff["not_settled_differs"] == ["t1/g/volt-var/0.0/connected/off"]
    with pytest.raises(InputError, match="no finished task"):
        compare_runs(tmp_path / "empty", tmp_path / "ref")
