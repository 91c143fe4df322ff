"""The study runner: the grid {case} × {strategy} × {k} × {night mode} × {forecast} over a
period, split into tasks (configuration × chunk of steps), run in process or on Dask,
checkpointed in a run folder (resumable) → per-step table + summary (`opfbench run`).
Not to be confused with `opfbench.bench`, the speed benchmarks."""

from opfbench.study.config import NIGHT_MODES, StudyConfig
from opfbench.study.periods import Period, resolve_period
from opfbench.study.runner import StudyRun, prepare, run_study

__all__ = ["NIGHT_MODES", "Period", "StudyConfig", "StudyRun", "prepare", "resolve_period", "run_study"]
