"""Your own local rule in one file: a proportional Q(V) droop, loaded as a plugin.

    opfbench strategies --plugin docs/custom_rule.py
    opfbench snapshot paper33 --plugin docs/custom_rule.py --strategy droop:gain=8
    opfbench run --plugin docs/custom_rule.py --strategies lfma volt-var droop droop:gain=10 --out reports/droop
    opfbench fault paper33 --plugin docs/custom_rule.py --strategies no-action lfma droop --fault-bus 18 --k 0

Each DER asks for Q = −gain·(|V| − v_ref)·S̄ MVAr (positive = injected): it injects below
v_ref and absorbs above it, `gain` p.u. of its nameplate S̄ per p.u. of voltage. The
engine (`opfbench.strategies.rule_engine`) does the rest, as for every built-in rule: it clips
the target to ±(1 − k)·Qmax (PV, DFIG or inverter capability, Algorithm 3's limit under a
forecast, "Q at night"), and — since the rule reads its own bus voltage, which its own Q
changes — solves it for the closed-loop steady state the inverter settles to (status
"not-settled" where that does not happen within the iteration limit).

Nothing in opfbench names this rule: `droop` and `droop:gain=10` appear in every table,
the manifest and the report, and run in `snapshot`, `run` (also on Dask workers, which
receive this file's source) and `fault`.
"""

from __future__ import annotations

import numpy as np

from opfbench.plugins import Option, local_rule


def _not_negative(value: object) -> str | None:
    return None if isinstance(value, float) and value >= 0 else f"a droop gain is ≥ 0, got {value}"


@local_rule(
    "droop",
    reads=("v",),
    options={
        "gain": Option("gain", 5.0, "p.u. of S̄ per p.u. of voltage", check=_not_negative),
        "v_ref": 1.0,
    },
    summary="proportional Q(V) droop: Q = −gain·(|V| − v_ref)·S̄ (docs/custom_rule.py)",
)
def droop(m, gain: float, v_ref: float) -> np.ndarray:
    """Q target (S, n_der) MVAr from the own-bus voltage m.v_pu (S, n_der) p.u."""
    return -gain * (m.v_pu - v_ref) * m.s_rated_mva
