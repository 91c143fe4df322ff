"""The study runner: the grid {case} × {strategy} × {k} × {night mode} × {forecast} over a
period → per-step table + summary (`opfbench run`). Not to be confused with
`opfbench.bench`, the speed benchmarks."""

from opfbench.study.runner import NIGHT_MODES, BenchmarkConfig, day_scenarios, run_benchmark, summarize

__all__ = ["NIGHT_MODES", "BenchmarkConfig", "day_scenarios", "run_benchmark", "summarize"]
