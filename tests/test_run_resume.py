"""A run killed (SIGKILL) at random moments and resumed each time ends with the same
table as an uninterrupted run: the same rows, no duplicates, bit-identical values (the
timing columns aside)."""

import multiprocessing
import random
import time

import pandas as pd

from opfbench.formulations import relaxation
from opfbench.study import StudyConfig, run_study
from opfbench.study.store import finished_tasks

# 4 k × 2 chunks (one per local day) = 8 tasks (each with 2 night modes) with the AC OPF
CONFIG = StudyConfig(
    strategies=("no-action", "lfma", "acopf"),
    ks=(0.0, 0.25, 0.5, 0.75),
    night_modes=("connected", "disconnected"),
    forecast=("off",),
    period="2016-06-28T23:30..2016-06-29T00:30",
    chunk="day",
    detail=False,
)
TIMING = ["wall_ms", "solver_ms"]
KEYS = ["case", "strategy", "k", "night_mode", "forecast", "time"]


def _child(out):
    relaxation.forget_solves()  # a fresh process would not have the parent's solves
    run_study(CONFIG, out, quiet=True)


def test_sigkill_at_random_moments_then_resume(tmp_path):
    ref = run_study(CONFIG, tmp_path / "ref", quiet=True)
    assert len(ref.tasks) == 8
    reference_s = ref.wall_s
    ctx = multiprocessing.get_context("fork")
    rng = random.Random(11)
    out = tmp_path / "killed"
    kills, finished = 0, False
    for _ in range(5):
        child = ctx.Process(target=_child, args=(out,))
        child.start()
        child.join(rng.uniform(0.05, 0.3) * reference_s)
        if child.exitcode is not None:
            assert child.exitcode == 0
            finished = True
            break
        child.kill()  # SIGKILL: no cleanup, lock left behind, maybe a half-written temporary file
        child.join(30)
        kills += 1
        time.sleep(0.05)
    assert kills >= 2
    kept = finished_tasks(out)
    resumed = run_study(CONFIG, out, quiet=True)
    assert resumed.kept == 8 and (finished or resumed.ran == 8 - kept)
    a = pd.read_parquet(ref.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(out / "steps.parquet").drop(columns=TIMING)
    assert not b.duplicated(KEYS).any() and len(b) == 3 * 4 * 2 * 60
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert not list(out.glob(".*")) and not list((out / "tasks").glob(".*"))  # no lock, no temporary files
