"""IPOPT through CasADi: the options, the cold and warm instances of an NLP, one solve's record.

Cold: a flat start and IPOPT's defaults. Warm: primal and dual start from a previous
solution (`warm_start_init_point`, small initial barrier). `bound_relax_factor = 0`:
IPOPT's iterates stay within the variable bounds, so the reported objective cannot dip
below a relaxation's bound by a bound overshoot. Every solve returns its status,
iterations and time from IPOPT's statistics.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

TOLERANCE = 1e-10  # IPOPT tol (scaled NLP error; objective in kW)
# IPOPT's gradient-based scaling shrinks the kW objective; without this extra factor the
# barrier leaves active Q bounds short of their limits and the objective above the exact
# SOCP bound by more than the certification's tolerance (`policy.CERTIFY_RTOL`).
OBJECTIVE_SCALING = 100.0
MAX_ITER = 300
IPOPT_OPTIONS: dict[str, Any] = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "record_time": True,
    "ipopt.tol": TOLERANCE,
    "ipopt.obj_scaling_factor": OBJECTIVE_SCALING,
    "ipopt.max_iter": MAX_ITER,
    "ipopt.bound_relax_factor": 0.0,  # iterates never leave the variable bounds
    # The KKT systems are small and sparse: skip MUMPS' scaling, AMD ordering (faster here).
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
    "ipopt.mumps_pivot_order": 0,
}
WARM_OPTIONS: dict[str, Any] = {
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-8,  # start near the previous (converged) barrier parameter
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
}
IPOPT_INFEASIBLE = {"Infeasible_Problem_Detected"}


@dataclass(frozen=True)
class IpoptSolve:
    """One IPOPT run. `status` is IPOPT's return status; `x`, `lam_x`, `lam_g` the final
    primal/dual point (the next warm start); `objective_kw` the NLP's objective (kW);
    `q_pu` the setpoint entries of x, within their bounds (p.u.)."""

    warm: bool
    success: bool
    status: str
    iterations: int
    solve_ms: float
    objective_kw: float
    q_pu: np.ndarray
    x: np.ndarray
    lam_x: np.ndarray
    lam_g: np.ndarray

    @property
    def infeasible(self) -> bool:
        return self.status in IPOPT_INFEASIBLE


class IpoptNlp:
    """IPOPT on one CasADi NLP (`nlp`: x, p, f, g), constraint bounds `lbg`..`ubg`; the
    decision entries `setpoints` of x are what a solve reports as `q_pu`. The cold and
    the warm instance are each created on first use (CasADi derives the NLP's Jacobian
    and Hessian per instance: the expensive part on large feeders). `options` override
    IPOPT_OPTIONS for this NLP."""

    def __init__(
        self, name: str, nlp: dict, lbg: np.ndarray, ubg: np.ndarray, setpoints: slice, options: dict[str, Any] | None = None
    ):
        self.name, self.nlp, self.lbg, self.ubg, self.setpoints = name, nlp, lbg, ubg, setpoints
        self.options = IPOPT_OPTIONS | (options or {})
        self._instances: dict[bool, ca.Function] = {}

    def instance(self, warm: bool) -> ca.Function:
        if warm not in self._instances:
            options = self.options | WARM_OPTIONS if warm else self.options
            self._instances[warm] = ca.nlpsol(f"{self.name}_{'warm' if warm else 'cold'}", "ipopt", self.nlp, options)
        return self._instances[warm]

    def solve(
        self,
        p: np.ndarray,
        lbx: np.ndarray,
        ubx: np.ndarray,
        x0: np.ndarray,
        start: IpoptSolve | None,
        lbg: np.ndarray | None = None,
        ubg: np.ndarray | None = None,
    ) -> IpoptSolve:
        """Solve at parameters `p` within the variable bounds `lbx`..`ubx` (and the
        constraint bounds `lbg`..`ubg`, default the NLP's): warm from `start`'s primal and
        dual point when given, else cold from `x0`."""
        lbg = self.lbg if lbg is None else lbg
        ubg = self.ubg if ubg is None else ubg
        args = {"p": p, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        solver = self.instance(warm=start is not None)
        if start is None:
            out = solver(x0=x0, **args)
        else:
            out = solver(x0=start.x, lam_x0=start.lam_x, lam_g0=start.lam_g, **args)
        stats = solver.stats()
        x = np.asarray(out["x"]).ravel()
        q = self.setpoints
        return IpoptSolve(
            warm=start is not None,
            success=bool(stats["success"]),
            status=str(stats["return_status"]),
            iterations=int(stats["iter_count"]),
            solve_ms=float(stats["t_wall_total"]) * 1e3,
            objective_kw=float(out["f"]),
            q_pu=np.clip(x[q], lbx[q], ubx[q]),  # a no-op with bound_relax_factor 0
            x=x,
            lam_x=np.asarray(out["lam_x"]).ravel(),
            lam_g=np.asarray(out["lam_g"]).ravel(),
        )
