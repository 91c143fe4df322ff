"""A real Dask cluster on localhost — a scheduler and two workers started as separate
processes, as on other machines — runs a small grid through `--scheduler`; the table is
bit-identical (timing columns aside) to the in-process run, and to a local cluster's."""

import pandas as pd

from opfbench.cli import main
from opfbench.study import StudyConfig, run_study

CONFIG = StudyConfig(
    strategies=("no-action", "lfma", "acopf", "socp"),
    ks=(0.0, 0.4),
    night_modes=("connected",),
    forecast=("off", "oracle"),
    period="2016-06-28T19:50..2016-06-28T20:10",
    detail=False,
)
TIMING = ["wall_ms", "solver_ms"]


def test_cluster_equals_in_process(dask_cluster, tmp_path):
    local = run_study(CONFIG, tmp_path / "local")
    assert len(local.tasks) == 2  # one per k: each runs both forecast sources
    args = [
        "run",
        "--period",
        CONFIG.period,
        "--strategies",
        *CONFIG.strategies,
        "--k",
        "0",
        "0.4",
        "--night-modes",
        "connected",
        "--no-detail",
        "--quiet",
    ]
    assert main([*args, "--scheduler", dask_cluster, "--out", str(tmp_path / "cluster")]) == 0
    a = pd.read_parquet(local.out / "steps.parquet").drop(columns=TIMING)
    b = pd.read_parquet(tmp_path / "cluster" / "steps.parquet").drop(columns=TIMING)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert (a.strategy == "acopf").sum() == 2 * 20 and set(a.night) == {False, True}
