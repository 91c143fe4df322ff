"""The benchmark modules report null for a peer that is not installed (JSON contract)."""

import builtins

import pytest

import opfbench.bench.opf as bench_opf
import opfbench.bench.pf as bench_pf


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
    for key in ("pandapower_loop_1440_ms", "ratio_vs_pandapower", "pgm_batch_1440_ms", "ratio_vs_pgm"):
        assert f[key] is None
    assert f["single_ms"] > 0 and f["batch_1440_ms"] > 0 and f["batch_converged"] == 1440
    bench_pf.print_table(f)
    assert "not installed" in capsys.readouterr().out


def test_opf_bench_without_peer(no_peers, capsys):
    f = bench_opf.bench_opf(n=6)
    assert f["pandapower_runopp_ms"] is None and f["ratio_ipopt_vs_pandapower"] is None
    assert f["solved"] == f["total"] == 6 and f["ipopt_ms"] > 0 and f["socp_ms"] > 0
    bench_opf.print_table(f)
    assert "pandapower not installed" in capsys.readouterr().out
