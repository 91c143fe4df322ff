"""The worked example `docs/custom_rule.py` end to end, as a researcher runs it: `opfbench
run` on two Dask worker processes (which load the plugin from the source the run ships
them), the report — rebuilt later without the plugin —, `snapshot` and `fault`; and no
file under opfbench/ changes, nor names the rule, to add it."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from opfbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = str(ROOT / "docs" / "custom_rule.py")
pytestmark = pytest.mark.usefixtures("isolated_registry")


def _package_digest() -> str:
    digest = hashlib.sha256()
    for path in sorted((ROOT / "opfbench").rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(ROOT)).encode() + path.read_bytes())
    return digest.hexdigest()


def test_the_example_runs_through_run_report_snapshot_and_fault(tmp_path, capsys):
    before = _package_digest()
    out = tmp_path / "run"
    argv = ["run", "--plugin", EXAMPLE, "--strategies", "no-action", "lfma", "droop", "droop:gain=10.0"]
    argv += ["--k", "0", "0.4", "--night-modes", "connected", "--period", "2016-06-28T11:00..2016-06-28T11:10"]
    argv += ["--workers", "2", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    steps = pd.read_parquet(out / "steps.parquet")
    droop = steps[steps["strategy"].isin(["droop", "droop:gain=10"])]
    assert set(droop["strategy"]) == {"droop", "droop:gain=10"} and set(droop["forecast"]) == {"off", "oracle"}
    assert (droop["status"] == "ok").all() and (droop["residual_mvar"] <= 1e-7).all() and (droop["power_flows"] > 1).all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config"]["plugins"] == [EXAMPLE] and len(manifest["config"]["plugin_digests"][0]) == 64
    summary = pd.read_csv(out / "summary.csv")
    assert {"droop", "droop:gain=10"} <= set(summary["strategy"]) and "not_settled_steps" in summary
    capsys.readouterr()
    # the report, rebuilt in a fresh process that never loaded the plugin, still shows it
    rebuilt = tmp_path / "report.html"
    subprocess.run([sys.executable, "-m", "opfbench", "report", str(out), "--out", str(rebuilt)], check=True, capture_output=True)
    html = rebuilt.read_text()
    assert "droop:gain=10" in html and "Leaderboard" in html
    assert main(["snapshot", "paper33", "--plugin", EXAMPLE, "--strategy", "droop:gain=8", "--json"]) == 0
    snap = json.loads(capsys.readouterr().out)
    assert snap["strategy"] == "droop:gain=8" and snap["status"] == "ok" and snap["power_flows"] > 1
    fault = ["fault", "paper33", "--plugin", EXAMPLE, "--strategies", "no-action", "droop", "--fault-bus", "18"]
    assert main([*fault, "--k", "0", "--t-end", "0.6", "--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert {r["strategy"] for r in records} == {"no-action", "droop"}
    assert _package_digest() == before
    named = subprocess.run(["grep", "-rl", "droop", str(ROOT / "opfbench")], capture_output=True, text=True).stdout
    assert named == ""  # opfbench knows nothing of the rule
