"""Benchmarks (wall time, not correctness). Each sub-benchmark is a function returning a
JSON-ready dict; `local.bench_local` times the local rules on a batched day."""
