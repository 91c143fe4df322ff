"""Benchmarks (not tests): `python -m opfbench.bench {pf,local,opf} [--json]`.

Each sub-benchmark times opfbench against a peer (pandapower, power-grid-model) run on
the same work in the same process and reports ratios, so the figures are comparable on
whatever machine runs them.
"""
