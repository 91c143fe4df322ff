"""Centralized formulations of the DER reactive-power dispatch (paper §III; README "What is inside").

- `problem`: the OPF problem written once — limits, slack rule, power-balance rows,
  AC feasibility of a point, per-snapshot inputs, status vocabulary, π-model branches.
  A new formulation supplies only its network model and objective (one file).
- `acopf`: the exact AC OPF in polar form (CasADi + IPOPT) with a certified fast path
  (SOCP setpoints that one batched AC power flow proves optimal skip IPOPT) and a
  recorded failure policy.
- `socp`: its second-order-cone relaxation (cvxpy + Clarabel) — DistFlow on radial
  feeders, Jabr's bus-injection SOC on meshed ones — whose optimum is a lower bound on
  the achievable losses; solved once per (scenario, k) for every caller.
- `conic`: re-solving a compiled cvxpy problem with Clarabel for new data.
- `cache`: per-thread solver objects, per-scenario shared solves.
- `dominance`: the check that the AC OPF is never beaten by a feasible strategy.
"""
