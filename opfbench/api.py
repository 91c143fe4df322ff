"""The Python API: what a notebook or a program uses — load a case, run a study with the
same checks as `opfbench run`, read its tidy tables as DataFrames, write the report.

    from opfbench import api

    case = api.load_case("paper33")                        # the network and its own series
    point = api.snapshot("paper33", "lfma", k=0.2)          # one operating point (StrategyResult)
    study = api.run_study(
        strategies=["no-action", "lfma", "acopf"], ks=[0, 0.4], night_modes=["connected"],
        forecast=["off"], period="2016-06-28T11:00..2016-06-28T13:00", out="runs/noon",
    )
    study.summary                                           # one row per configuration
    study.steps()                                           # one row per configuration × step
    api.write_report(study.out)                             # runs/noon/report.html

Bad input raises one of `opfbench.errors`' exceptions (`InputError` and its kinds: what
the CLI turns into exit code 2), before any work. The API never prints and never ends the
process: a study's notes are in `Study.notes`, its progress goes to `progress(done,
total)`, and Ctrl-C stops it with `opfbench.errors.Stopped` once the running task is saved
(the same call resumes). Each `run_study` ends by resetting the process state
(`state.PROCESS`): the plugins it loaded leave the registry, fitted rules and caches are
forgotten, so a second study in the same process starts as the first one did. The tables'
columns are `opfbench.schema`'s (docs/CONTRACTS.md).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from opfbench.capability import PAPER_KS
from opfbench.io import Case
from opfbench.registry.references import DEFAULT_RUN
from opfbench.result import StrategyResult
from opfbench.state import PROCESS
from opfbench.study.config import NIGHT_MODES, StudyConfig
from opfbench.study.engine import Reporter, TaskOutput

__all__ = ["Study", "load_case", "run_study", "snapshot", "write_report"]


def load_case(spec: str) -> Case:
    """The case `spec` names — a shipped name, a MATPOWER `.m` or pandapower `.json` path,
    `simbench:CODE`, with `?der=…` options (`opfbench.io`); InputError naming it otherwise."""
    from opfbench.io import load_case as load

    return load(spec)


def snapshot(
    case: str | Case, strategy: str, k: float = 0.0, load_scale: float = 1.0, der_scale: float = 0.8, plugins: Sequence[str] = ()
) -> StrategyResult:
    """One operating point of `case` — every load at `load_scale` of nominal, every DER at
    `der_scale` of its rating — under the configuration `strategy` (`NAME[:key=value,…]`) at
    reserve k, as `opfbench snapshot` runs it; `plugins`: files or modules to load first."""
    from opfbench.plugins import load
    from opfbench.registry.catalog import configuration
    from opfbench.scenario import Scenario

    for ref in plugins:
        load(ref)
    config = configuration(strategy)
    net = (load_case(case) if isinstance(case, str) else case).balanced(
        "a snapshot (for now only `pf` and `cases` read three-phase feeders)"
    )
    return config.run(Scenario.snapshot(net, load_scale, der_scale), k)


@dataclass
class Study:
    """A finished study: its folder (`out`), configuration, summary (one row per
    configuration), notes, and the tasks run now and kept from an earlier call."""

    out: Path
    config: StudyConfig
    summary: pd.DataFrame
    notes: list[str] = field(default_factory=list)
    ran: int = 0
    kept: int = 0

    def steps(self, columns: Sequence[str] | None = None, **equal: Any) -> pd.DataFrame:
        """The per-step table (`schema.STEPS`), its `columns` only where given, its rows
        where each keyword's column equals its value (e.g. `strategy="lfma", k=0.4`)."""
        return self._table("steps", columns, equal)

    def der_q(self, columns: Sequence[str] | None = None, **equal: Any) -> pd.DataFrame:
        """The per-DER setpoints (`schema.DER_Q`), when the study wrote them."""
        return self._table("der_q", columns, equal)

    def frontier(self, columns: Sequence[str] | None = None, **equal: Any) -> pd.DataFrame:
        """The frontier of losses against voltage compliance per step and ε
        (`schema.FRONTIER`), which every configuration is compared with at its own
        compliance (`summary`'s `gap_eq_kwh`, `share_eq_pct`)."""
        return self._table("frontier", columns, equal)

    def _table(self, name: str, columns: Sequence[str] | None, equal: dict[str, Any]) -> pd.DataFrame:
        path = self.out / f"{name}.parquet"
        if not path.is_file():
            from opfbench.errors import InputError

            raise InputError(f"{self.out} has no {name}.parquet (a study writes der_q.parquet with detail=True)")
        filters = [(key, "==", value) for key, value in equal.items()] or None
        frame = pd.read_parquet(path, columns=list(columns) if columns else None, filters=filters)
        return frame.astype({c: str for c in frame.columns if isinstance(frame[c].dtype, pd.CategoricalDtype)})


class _Progress:
    def __init__(self, report: Callable[[int, int], None], total: int, done: int):
        self.report, self.total, self.done = report, total, done

    def update(self, result: TaskOutput) -> None:
        self.done += 1
        self.report(self.done, self.total)

    def close(self) -> None:
        pass


def run_study(
    *,
    cases: Sequence[str] = ("paper33",),
    strategies: Sequence[str] = DEFAULT_RUN,
    ks: Sequence[float] = PAPER_KS,
    night_modes: Sequence[str] = NIGHT_MODES,
    forecast: Sequence[str] = ("off", "oracle"),
    period: str = "paper-day",
    out: str | Path | None = None,
    plugins: Sequence[str] = (),
    workers: int | None = 1,
    fresh: bool = False,
    progress: Callable[[int, int], None] | None = None,
    **options: Any,
) -> Study:
    """Run a study as `opfbench run` does — every case × configuration × k × night mode ×
    forecast over `period` — into the folder `out` (a new temporary folder where None; an
    earlier run's folder resumes). `plugins`: files or modules to load first; `workers`:
    local worker processes (1: in this process; None: one per core); `options`: the other
    fields of `study.config.StudyConfig` (`night`, `step_minutes`, `detail`, `acopf_solver`,
    …). The checks are the CLI's; the state the study leaves is reset when it ends (module
    docstring)."""
    from opfbench.plugins import load
    from opfbench.study.run_family import run_study as run

    folder = Path(tempfile.mkdtemp(prefix="opfbench-study-")) if out is None else Path(out)
    sink = None if progress is None else (lambda total, done: _Progress(progress, total, done))
    with PROCESS.scope():
        for ref in plugins:
            load(ref)
        config = StudyConfig.build(
            cases=tuple(cases),
            strategies=tuple(strategies),
            ks=tuple(float(k) for k in ks),
            night_modes=tuple(night_modes),
            forecast=tuple(forecast),
            period=period,
            **options,
        )
        done = run(config, folder, workers=workers, fresh=fresh, reporter=Reporter(progress=sink))
    assert done.summary is not None, "a finished run has its summary"
    notes = [*config.notes, *done.notes]
    return Study(done.out, done.config, done.summary, notes, done.ran, done.kept)


def write_report(folder: str | Path, out: str | Path | None = None) -> Path:
    """The run folder's report (`folder/report.html`, or `out`); InputError for a folder
    that is no run's."""
    from opfbench.report import write_report as write

    return write(Path(folder), out=Path(out) if out is not None else None)
