"""Centralized formulations of the DER reactive-power dispatch (SPEC §3).

- `acopf`: the exact AC OPF in polar form (CasADi + IPOPT), built once per network and
  re-solved per snapshot with warm start, with a recorded failure policy.
- `socp`: its second-order-cone relaxation (cvxpy + Clarabel) — DistFlow on radial
  feeders, Jabr's bus-injection SOC on meshed ones — whose optimum is a lower bound on
  the achievable losses.
- `common`: what both share: per-snapshot inputs in per unit, π-model branch
  coefficients, the status vocabulary, AC feasibility of a point, the dominance check.
"""
