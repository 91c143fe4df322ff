"""Communication-free local reactive-power rules (paper §III).

- `engine`: the one engine of local rules (measure → set → the grid answers; the
  closed-loop steady state of rules that read |V| or line flows).
- `paper`: the runners `no_action`, `llma` (Algorithm 1) and `lfma` (Algorithm 2), each
  with Algorithm 3 (forecast-aware limits) when the scenario carries a forecast.
- `limits`: the symmetric reactive bound each rule may use (reserve k, forecast, safe).
- `meters`: what a DER sees locally — reactive flows on the lines at its own bus.

Sign conventions: Q positive = injected by the DER into the grid; a bus's upstream
inflow Q_up is positive when the bus imports reactive power from its upstream line;
downstream outflow Q_do is positive when reactive power leaves the bus into its other lines.
"""
