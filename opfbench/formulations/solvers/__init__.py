"""Solver adapters: how the formulations' models are handed to a solver and read back.

- `clarabel_adapter`: Clarabel's settings for the relaxations, and a cvxpy conic problem
  compiled once and re-solved per snapshot with bound screening;
- `ipopt_adapter`: IPOPT's options, cold and warm instances of a CasADi NLP, one solve's record.
"""
