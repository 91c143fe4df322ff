"""Where the SDP bound loses exactness on a feeder (`python docs/sdp_gap_diagnosis.py
[--steps N] [CASE]`, Markdown on stdout; default ieee123, the steps of
`unbalanced_opf_table.py --taps held` where the AC optimum exists; its output is in
`docs/unbalanced_opf_table.md`).

Per step, the relative gap (AC optimum − bound) / AC optimum of:
- the relaxation as `formulations.three_phase.bound` solves it;
- the relaxation with each DER's Q held at the AC optimum's (what the relaxation loses at
  the same decisions: its power flow is loose there), and what that solution holds:
  the constant-|I| loads' power below their law (kW, the hull of u = √w between its curve
  and its chord, `sdp_three_phase`), and the losses of each branch's block against the
  AC point lifted (W: a block whose losses fall below the AC point's; the largest two);
- the same feeder with its constant-|I| loads as constant impedance (an exact law in the
  relaxation), AC optimum and relaxation at held Q both re-solved — the gap left without
  the hull;
- the AC optimum lifted into the relaxation (rank one): its objective against the power
  flow's losses (the ideal switches' losses, which the relaxation drops: `Z_IDEAL`).
And the largest rank ratio over the blocks with the block's name."""

from __future__ import annotations

import argparse
import dataclasses

import cvxpy as cp
import numpy as np
from unbalanced_opf_table import snapshots

from opfbench.formulations.models.sdp_three_phase import ThreePhaseSdp
from opfbench.formulations.three_phase import optimum, q_limits
from opfbench.multiphase import PhaseNetwork
from opfbench.multiphase.branches import CONSTANT_I, CONSTANT_Z


def _held(net: PhaseNetwork) -> tuple[ThreePhaseSdp, cp.Parameter]:
    """The relaxation with the DER's Q held at a parameter."""
    model = ThreePhaseSdp(net)
    q = next(v for v in model.problem.variables() if v.name() == "q")
    held = cp.Parameter(q.size, name="q_held")
    model.problem = cp.Problem(model.problem.objective, [*model.problem.constraints, q == held])
    return model, held


def _block_losses(model: ThreePhaseSdp, x: np.ndarray) -> dict[str, float]:
    """Each branch block's own term of the objective (kW) at the unknowns x."""
    names = {blk: br.name for br, blk, _, _ in model._coords}
    out = {}
    for blk in model._blocks:
        off, size = model._gram.offsets[blk], model._gram.sizes[blk] ** 2
        part = np.zeros_like(x)
        part[off : off + size] = x[off : off + size]
        model._x.value = part
        out[names.get(blk, f"load/DER block {blk}")] = float(model.problem.objective.value)
    model._x.value = x
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", nargs="?", default="ieee123")
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()
    net, lp, lq, dp, times, _, _ = snapshots(args.case, args.steps, "held")
    opt = optimum(net, lp, lq, dp, 0.0)
    rows = np.flatnonzero(np.isfinite(opt.objective_kw))
    lm = net.load_models
    as_z = dataclasses.replace(net, load_models=dataclasses.replace(lm, model=np.where(lm.model == CONSTANT_I, CONSTANT_Z, lm.model)))
    opt_z = optimum(as_z, lp[rows], lq[rows], dp[rows], 0.0)
    free, (held, q_held), (held_z, q_held_z) = ThreePhaseSdp(net), _held(net), _held(as_z)
    names = {blk: br.name for br, blk, _, _ in free._coords}
    constant_i = lm.model[net.load_branches.owner] == CONSTANT_I
    print(
        "| step | AC optimum kW | gap | gap, Q held | const-|I| loads below their law, Q held (kW) | blocks below the AC point, Q held (W) "
        "| gap, const-|I| as const-Z, Q held | lifted AC optimum − its losses (W) | largest rank ratio (block) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for j, i in enumerate(rows):
        snap = (lp[i], lq[i], dp[i], q_limits(net, dp[i : i + 1], 0.0)[0])
        ac = opt.losses_kw[i]
        cells = [times[i], f"{ac:.4f}"]
        solved = free.solve(*snap)
        cells.append(f"{(ac - solved.bound_kw) / ac:.2e} ({solved.status})")
        ratios = free.rank_ratios() if solved.status == "optimal" else np.array([np.nan])
        worst = int(np.nanargmax(ratios)) if np.isfinite(ratios).any() else 0
        rank = f"{ratios[worst]:.1e} ({names.get(free._blocks[worst], 'load/DER block')})" if np.isfinite(ratios).any() else "—"
        q_held.value = opt.q_mvar[i]
        at_q = held.solve(*snap)
        cells.append(f"{(ac - at_q.bound_kw) / ac:.2e} ({at_q.status})")
        if at_q.status == "optimal":
            x = held._x.value.copy()
            s_p = next(v for v in held.problem.variables() if v.name() == "s_p").value
            lb = net.load_branches
            w = held._pair_w(lb.a, lb.b, lb.vbase_v).value
            below = lb.share * lp[i][lb.owner] * (held._law(w)[0] - s_p)
            mine = _block_losses(held, x)
            held.lift(opt.flow.v[i], *snap, opt.q_mvar[i])
            theirs = _block_losses(held, held._x.value)
            diff = sorted((mine[k] - theirs[k], k) for k in mine)[:2]
            cells += [f"{1e3 * below[constant_i].sum():.3f}", ", ".join(f"{k} {1e3 * d:.2f}" for d, k in diff)]
        else:
            cells += ["—", "—"]
        q_held_z.value = opt_z.q_mvar[j]
        at_z = held_z.solve(*snap)
        ac_z = opt_z.losses_kw[j]
        cells.append(f"{(ac_z - at_z.bound_kw) / ac_z:.2e} ({at_z.status})")
        free.lift(opt.flow.v[i], *snap, opt.q_mvar[i])
        cells += [f"{1e3 * (free.problem.objective.value - ac):.3f}", rank]
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
