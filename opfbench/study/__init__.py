"""The one study engine (`engine`: a task family's tasks → checkpoint store → in process
or Dask → tables; `opfbench run` and `opfbench fault` both use it) and the run's study:
the grid {case} × {strategy} × {k} × {night mode} × {forecast} over a period, split into
tasks (configuration × chunk of steps) → per-step table + summary (`opfbench run`).
Not to be confused with `opfbench.bench`, the speed benchmarks."""

from opfbench.study.config import NIGHT_MODES, StudyConfig

__all__ = ["NIGHT_MODES", "Period", "StudyConfig", "StudyRun", "prepare", "resolve_period", "run_study"]
_LAZY = {
    "Period": "periods",
    "resolve_period": "periods",
    "StudyRun": "run_family",
    "prepare": "run_family",
    "run_study": "run_family",
}  # pandas and the solvers load on first use, not with the CLI


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"opfbench.study.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'opfbench.study' has no attribute {name!r}")
