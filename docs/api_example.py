"""The Python API in one script (README, "Python API"): load a case, evaluate one operating
point, run a small study with the CLI's checks, read its tidy tables, write its report.

    python docs/api_example.py [OUT]        (OUT: the run folder, default reports/api-example)

Run by tests/test_api.py.
"""

import sys

from opfbench import api

out = sys.argv[1] if len(sys.argv) > 1 else "reports/api-example"

case = api.load_case("paper33")
net = case.network
print(f"{net.name}: {net.n_bus} buses, {len(net.ders)} DER ({', '.join(net.der_names)})")

point = api.snapshot("paper33", "lfma", k=0.2)  # every load nominal, every DER at 80 % of its rating
print(f"LFMA on one operating point: {point.losses_kw[0]:.2f} kW, |V| {point.vmin[0]:.4f}…{point.vmax[0]:.4f} p.u.")

study = api.run_study(
    strategies=["no-action", "lfma", "lindistflow", "acopf"],
    ks=[0.0, 0.4],
    night_modes=["connected"],
    forecast=["off"],
    period="2016-06-28T11:00..2016-06-28T12:00",
    out=out,
)
print(study.summary[["strategy", "k", "energy_kwh", "savings_pct", "gap_eq_kwh", "not_ok_steps"]].to_string(index=False))
steps = study.steps(["time", "losses_kw", "status"], strategy="lfma", k=0.4)
print(f"LFMA at k = 0.4: {len(steps)} steps, peak losses {steps['losses_kw'].max():.2f} kW")
front = study.frontier(["eps_pu", "cost_kw"], k=0.4)  # the optimum with the band widened by ε, per step
print(f"frontier at k = 0.4: {front['eps_pu'].nunique()} widenings ε of the band, {len(front)} rows")
print(f"report: {api.write_report(study.out)}")
