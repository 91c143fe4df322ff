"""The network models of the OPF problem (`formulations.problem`), one module each:

- `soc`: what every second-order-cone relaxation shares (cvxpy variables for the data,
  limits, balance rows, objective; the read-out of a solve), `SocpSolve`;
- `distflow`: DistFlow (branch flow) SOC, radial feeders;
- `jabr`: Jabr's bus-injection SOC, any feeder;
- `polar_ac`: the exact AC OPF in polar form (CasADi NLP).

A model writes its variables and branch flows into the problem's rows; the solvers
(`formulations.solvers`) and the policy above them (`formulations.policy`) are shared.
"""
