"""Benchmarks run by hand (`python -m opfbench.bench.<name>`), not by the test suite:
timings on a shared machine are noisy, so they are measured and reported, never asserted."""
