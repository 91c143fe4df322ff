"""A formulation from outside opfbench, as a researcher adds one: a model class in a file of
its own, decorated with `@opfbench.plugins.formulation`, loaded with `--plugin` like a local
rule, and run through `snapshot`, `run` (the generic runner: AC evaluation, statuses, the
solver record in the tables) and the report — with no file under opfbench/ edited."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pandas as pd
import pytest

from opfbench.cli import main

pytestmark = pytest.mark.usefixtures("isolated_registry")

FLAT_VOLTAGE = '''
import cvxpy as cp

from opfbench.formulations.models.conic import ConicModel
from opfbench.formulations.models.distflow import RadialBranches
from opfbench.formulations.problem import incidence
from opfbench.plugins import formulation


@formulation("flat-v", role="approximation", networks=("radial",), summary="test: the flattest voltages on LinDistFlow")
class FlatVoltage(ConicModel):
    """Lossless branch flows, linear voltage drops; minimize Σ (|V|² − 1)² (a quadratic
    objective with a constant term)."""

    def _network_model(self):
        br = RadialBranches.of(self.net)
        at = incidence(br.parent, self.net.n_bus) - incidence(br.child, self.net.n_bus)
        p, q = cp.Variable(br.child.size), cp.Variable(br.child.size)
        mismatch_p = at @ p - self.p_fixed
        mismatch_q = at @ q - self.q_fixed - self._der_q_at_buses()
        drop = [self.v[br.child] == self.v[br.parent] - 2 * (cp.multiply(br.r, p) + cp.multiply(br.x, q))]
        self._p, self._from_slack = p, br.parent == self.net.slack
        return mismatch_p, mismatch_q, cp.sum_squares(self.v - 1) / self.problem.kw_per_pu, drop

    def _slack_p_pu(self, value, thetas, objective_kw):
        return value(self._p)[:, self._from_slack].sum(axis=1) - thetas[:, self.net.slack]
'''


def test_a_formulation_plugin_runs_through_snapshot_run_and_the_report(tmp_path, capsys):
    plugin = tmp_path / "flat_voltage.py"
    plugin.write_text(textwrap.dedent(FLAT_VOLTAGE))
    assert main(["snapshot", "paper33", "--plugin", str(plugin), "--strategy", "flat-v", "--json"]) == 0
    snap = json.loads(capsys.readouterr().out)
    assert snap["status"] == "ok" and snap["model"] == "flat-v" and snap["objective"] == "estimate"
    assert snap["solver_status"] == "Solved" and snap["fallback"] == "none" and snap["vmax"] > snap["vmin"]
    out = tmp_path / "run"
    argv = ["run", "--plugin", str(plugin), "--strategies", "no-action", "flat-v", "--k", "0", "--night-modes", "connected"]
    argv += ["--period", "2016-06-28T11:00..2016-06-28T11:05", "--workers", "1", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    steps = pd.read_parquet(out / "steps.parquet")
    flat = steps[steps["strategy"] == "flat-v"]
    assert len(flat) == 5 and (flat["status"] == "ok").all() and (flat["solver_status"] == "Solved").all()
    assert (flat["iterations"] > 0).all() and (flat["certified_by"] == "").all() and flat["lower_bound_kw"].isna().all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["strategies"]["flat-v"] == {
        "kind": "formulation",
        "summary": "test: the flattest voltages on LinDistFlow",
        "source": str(plugin),
        "uses_forecast": False,
        "lower_bound": False,
        "role": "approximation",
        "objective": "estimate",
    }
    # the report, rebuilt in a process that never loaded the plugin, counts flat-v among the
    # formulations — by what the run folder says (the registry there does not know it)
    rebuilt = tmp_path / "rebuilt.html"
    subprocess.run([sys.executable, "-m", "opfbench", "report", str(out), "--out", str(rebuilt)], check=True, capture_output=True)
    for html in ((out / "report.html").read_text(), rebuilt.read_text()):
        convergence = html.split('<section id="convergence"')[1].split("<section")[0]
        assert '<td class="nw">flat-v</td>' in convergence and '<td class="nw">no-action</td>' not in convergence
