"""Centralized formulations of the DER reactive-power dispatch (paper §III), split the way
PowerModels keeps formulations, problems and solvers apart. Data flows down this list:

- `options`: the option vocabularies (AC OPF solver path, failure policy), light to import.
- `problem`: the OPF problem written once — limits, slack rule, power-balance rows, AC
  feasibility of a point, per-snapshot inputs, π-model branches.
- `models/`: the network models of that problem, one module each — `distflow` (DistFlow
  SOC, radial), `jabr` (bus-injection SOC, any feeder) on `soc` (what the relaxations
  share), `polar_ac` (the exact AC OPF, an NLP). A new model is one file.
- `solvers/`: the solver adapters — `clarabel_adapter` (settings, a compiled conic program
  re-solved per snapshot with bound screening), `ipopt_adapter` (options, cold and warm
  instances).
- `cache`: per-thread solver objects and the solve cache keyed on the data.
- `relaxation`: the relaxation of a network (model chosen by topology) and its solves on
  every snapshot, shared by data.
- `infeasibility`: sound proofs that the AC OPF of a snapshot has no feasible point
  (interval bounds on the exact branch flows of a radial feeder): the slack must export,
  a voltage limit out of reach — what the relaxation cannot show.
- `policy`: the certified fast path and the failure policies (chain, paper) that settle
  each snapshot of the AC OPF.
- `results`: answers → the one result record (`StrategyResult`), AC-evaluated.
- `acopf`, `socp`: the strategies the registry runs (`run_acopf`, `run_socp`).
"""
