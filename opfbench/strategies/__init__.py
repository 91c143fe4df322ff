"""Communication-free local reactive-power rules (paper §III).

- `rules`: what a local rule is — a function of the DER's own measurements — and what it reads.
- `rule_engine`: the one engine of local rules (measure → set → the grid answers; the
  closed-loop steady state of rules that read |V| or line flows).
- `registration`: `@local_rule`, how a rule joins the registry (built-ins and plugins),
  and the engine's options every rule takes.
- `paper`: no action, LLMA (Algorithm 1) and LFMA (Algorithm 2), each with Algorithm 3
  (forecast-aware limits) when the scenario carries a forecast.
- `standards`: the rules grid codes mandate (IEEE 1547-2018, VDE-AR-N 4105 and 4110).
- `limits`: the symmetric reactive bound each rule may use (reserve k, forecast, safe).
- `meters`: what a DER sees locally — reactive flows on the lines at its own bus.
- `sensitivity`: ∂|V|/∂Q at the DER buses and the slope bound it gives (learned rules).

Sign conventions: Q positive = injected by the DER into the grid; a bus's upstream
inflow Q_up is positive when the bus imports reactive power from its upstream line;
downstream outflow Q_do is positive when reactive power leaves the bus into its other lines.
"""
