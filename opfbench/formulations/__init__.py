"""Centralized formulations of the DER reactive-power dispatch (paper §III), split the way
PowerModels keeps formulations, problems and solvers apart. Data flows down this list:

- `acopf_options`: the AC OPF's option vocabularies (solver path, failure policy), light to import.
- `problem`: the OPF problem written once — limits, slack rule, power-balance rows, AC
  feasibility of a point, per-snapshot inputs, π-model branches.
- `model`: what a formulation model is (its role — exact, relaxation, approximation — says
  what its objective means: optimum, bound, estimate), the `@formulation` registration
  that built-in models and plugins use alike, and which model serves the OPF problem on
  which network (`model_for`).
- `models/`: the models, one file each, found by `model.load_models` — `polar_ac` (the
  exact AC OPF, an NLP), `distflow` (DistFlow SOC, radial) and `jabr` (bus-injection SOC,
  any feeder), `lindistflow` (the linearized branch flow, an approximation), on `conic`
  (what every conic model shares). A new model is one file there, or a plugin.
- `solvers/`: the solver adapters — `clarabel_adapter` (settings, a compiled conic program
  with a linear or quadratic objective re-solved per snapshot with bound screening),
  `ipopt_adapter` (options, cold and warm instances).
- `solver_cache`: per-thread solver objects and the solve cache keyed on the data.
- `solves`: a relaxation's or approximation's solves on every snapshot, shared by data.
- `infeasibility`: sound proofs that the AC OPF of a snapshot has no feasible point
  (interval bounds on the exact branch flows of a radial feeder): the slack must export,
  a voltage limit out of reach — what the relaxation cannot show.
- `policy`: the certified fast path and the failure policies (chain, paper) that settle
  each snapshot of an exact model.
- `evaluation`: answers → the one result record (`StrategyResult` with its `SolverRecord`),
  AC-evaluated.
- `runner`: the one runner of every model (fallback chain, statuses, certification).
- `opf_strategies`: the OPF problem's strategies, `acopf`, `acopf-paper` and `socp`.
"""
