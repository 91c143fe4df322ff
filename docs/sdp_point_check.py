"""Is the SDP relaxation's solution an operating point? (`python docs/sdp_point_check.py
[CASE] [--steps N] [--at I …]`, Markdown on stdout; default eulv, the steps of
`unbalanced_opf_table.py`, all of them unless `--at` picks some.)

Per step: the AC optimum's losses; the relaxation's status and value (`ThreePhaseSdp.solve`:
a bound only where "optimal"; an almost-solved value is shown, never a bound), its largest
rank ratio; our power flow at the relaxation's DER Q (its losses, its voltage range against
the band, whether it converged) and the largest |ΔQ| against the AC optimum's; and what the
load branches draw above their law at the relaxation's voltages (kW: the sum, the smallest
and the largest; the count of loads above their vmaxpu). A rank-one solution whose loads
draw their law is the power flow's point; one whose loads draw above it sits inside the
hull of the constant-PQ law (`sdp_three_phase`), lower than any operating point can."""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from unbalanced_opf_table import snapshots

from opfbench.formulations.models.sdp_three_phase import ThreePhaseSdp
from opfbench.formulations.three_phase import optimum, q_limits
from opfbench.powerflow.multiphase import solve_phase_flow


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", nargs="?", default="eulv")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--at", type=int, nargs="*", help="step indices (0-based) among --steps")
    args = parser.parse_args()
    net, lp, lq, dp, times, _, _ = snapshots(args.case, args.steps)
    at = np.array(args.at if args.at else range(args.steps))
    opt = optimum(net, lp[at], lq[at], dp[at], 0.0)
    model = ThreePhaseSdp(net)
    lb, lm = net.load_branches, net.load_models
    print(
        "| step | AC optimum kW | SDP status | SDP value kW | (AC − value)/AC | rank ratio | power flow at its Q: kW, V range p.u., converged "
        "| max |ΔQ| vs AC (kvar) | loads above their law: Σ kW (min, max) | loads above vmaxpu |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for j, i in enumerate(at):
        ac = opt.losses_kw[j]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            solved = model.solve(lp[i], lq[i], dp[i], q_limits(net, dp[i : i + 1], 0.0)[0])
        value = model.problem.value
        if value is None:
            print(f"| {times[i]} | {ac:.9f} | {solved.status} | — | — | — | — | — | — | — |", flush=True)
            continue
        q = model.q.value
        flow = solve_phase_flow(net, lp[i : i + 1], lq[i : i + 1], dp[i : i + 1], der_q_mvar=q[None], tol=1e-12, max_iter=500)
        w = model._pair_w(lb.a, lb.b, lb.vbase_v).value
        above = 1e3 * lb.share * lp[i][lb.owner] * (model.problem.var_dict["s_p"].value - model._law(w)[0])
        print(
            f"| {times[i]} | {ac:.9f} | {solved.status} | {value:.9f} | {(ac - value) / ac:.2e} | {model.rank_ratios().max():.1e} "
            f"| {flow.losses_kw[0]:.9f}, {flow.vm[0].min():.4f}–{flow.vm[0].max():.4f}, {bool(flow.converged[0])} "
            f"| {1e3 * np.abs(q - opt.q_mvar[j]).max():.4f} | {above.sum():.4f} ({above.min():.1e}, {above.max():.1e}) "
            f"| {int((w > lm.vmaxpu[lb.owner] ** 2).sum())}/{lb.n} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
