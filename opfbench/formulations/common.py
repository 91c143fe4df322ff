"""What the AC OPF and its SOCP relaxation share.

Units and signs: everything inside the formulations is per unit on `net.base_mva`
(voltages p.u., powers p.u., squared magnitudes p.u.²); results are converted to MVAr and
kW at the boundary. Injections are positive into the grid, DER Q positive = injected.

Every model is written with the same *bus mismatch*, the power a bus pushes into its
branches and shunt minus what it is given:

    mismatch_p[i] = Σ branch P leaving i + gsh_i·v_i − p_fixed_i
    mismatch_q[i] = Σ branch Q leaving i − bsh_i·v_i − q_fixed_i − (DER Q at i)

with v_i = |V_i|². It is zero at every non-slack bus; at the slack bus it is what the
external grid injects (slack P/Q). `losses` always means the branch losses (series and
charging), the quantity `PowerFlowResult.losses_kw` reports.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable

import numpy as np
import scipy.sparse as sp

from opfbench.capability import check_reserve
from opfbench.errors import NetworkError
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult, solve_pf_batch
from opfbench.result import INFEASIBLE, OK, StrategyResult
from opfbench.scenario import Scenario

# ----- status vocabulary (StrategyResult.status) -------------------------------------
FALLBACK_COLD = "fallback-cold"  # warm IPOPT failed, cold IPOPT from a flat start solved it
FALLBACK_SOCP = "fallback-socp"  # IPOPT failed; the SOCP's setpoints, AC-evaluated, are feasible
FALLBACK_NO_ACTION = "fallback-no-action"  # nothing better found; Q = 0 is AC-feasible
SOLVER_FAILED = "solver-failed"  # solver failed, no feasible fallback, infeasibility not shown
STATUSES = (OK, FALLBACK_COLD, FALLBACK_SOCP, FALLBACK_NO_ACTION, INFEASIBLE, SOLVER_FAILED)

# ----- which point a snapshot's setpoints come from (extra["fallback"]) ------------------
FROM_SOLVER = "none"  # the formulation's own solution
FROM_COLD = "cold"
FROM_SOCP = "socp"
FROM_NO_ACTION = "no-action"

VOLTAGE_TOLERANCE = 1e-6  # p.u.: a point is within limits up to this
SLACK_P_TOLERANCE = 1e-6  # MW: slack "does not export" up to this


def kw_per_pu(net: Network) -> float:
    """Factor from active power in p.u. on `net.base_mva` to kW."""
    return net.base_mva * 1e3


@dataclass(frozen=True)
class SnapshotData:
    """The OPF inputs of every snapshot, per unit on the network's base.

    s_fixed (S, n_bus) complex: every injection the OPF does not decide — fixed
    generators + DER active power − load_scale·load (positive into the grid).
    q_limit (S, n_der) ≥ 0: usable (1 − k)·Qmax; each DER's Q lies in [−q_limit, q_limit].
    """

    s_fixed: np.ndarray
    q_limit: np.ndarray

    @property
    def n_snapshots(self) -> int:
        return self.s_fixed.shape[0]


def snapshot_data(scenario: Scenario, k: float) -> SnapshotData:
    """Per-unit inputs of `scenario` with reserve coefficient k (InputError outside [0, 1])."""
    check_reserve(k)
    net = scenario.net
    check_supported(net)
    zero_q = np.zeros_like(scenario.der_p_mw)
    s_fixed = scenario.injections(zero_q) / net.base_mva
    q_limit = (1.0 - check_reserve(k)) * scenario.qmax_mvar() / net.base_mva
    return SnapshotData(s_fixed, q_limit)


def check_supported(net: Network) -> None:
    """Refuse what the formulations do not model, with the reason."""
    if net.pv_buses.size:
        ids = ", ".join(str(b) for b in net.bus_ids[net.pv_buses])
        raise NetworkError(f"{net.name}: the OPF formulations do not model voltage-controlled (PV) buses ({ids})")
    if np.any(net.der_bus == net.slack):
        raise NetworkError(f"{net.name}: a DER at the slack bus has no effect on the network; move it or drop it")


def incidence(rows: np.ndarray, n_rows: int) -> sp.csr_matrix:
    """(n_rows, len(rows)) sparse 0/1 matrix with a 1 at (rows[k], k): sums column
    quantities (branch ends, DER units) onto buses."""
    rows = np.asarray(rows, dtype=int)
    return sp.csr_matrix((np.ones(rows.size), (rows, np.arange(rows.size))), shape=(n_rows, rows.size))


Mul = Callable[[np.ndarray, Any], Any]  # elementwise constant × expression of the modelling tool


@dataclass(frozen=True, eq=False)
class PiBranches:
    """In-service π-model branches, flows written in the entries of W = V·Vᴴ.

    For branch l from f to t, with v_f = |V_f|², v_t = |V_t|² and V_f·conj(V_t) = c + j·s:

        P_f = gff·v_f + gft·c + bft·s        Q_f = −bff·v_f + gft·s − bft·c
        P_t = gtt·v_t + gtf·c − btf·s        Q_t = −btt·v_t − gtf·s − btf·c

    where yff = gff + j·bff, … are MATPOWER's branch admittances (taps, phase shifts and
    line charging included), flows positive leaving the bus into the branch. The AC OPF
    substitutes c = |V_f||V_t|·cos(θ_f − θ_t), s = |V_f||V_t|·sin(θ_f − θ_t); Jabr's
    relaxation keeps c, s free subject to c² + s² ≤ v_f·v_t.
    """

    f: np.ndarray
    t: np.ndarray
    yff: np.ndarray
    yft: np.ndarray
    ytf: np.ndarray
    ytt: np.ndarray
    at_from: sp.csr_matrix  # (n_bus, n_br) 1 at (f[l], l)
    at_to: sp.csr_matrix  # (n_bus, n_br) 1 at (t[l], l)

    @classmethod
    def of(cls, net: Network) -> "PiBranches":
        on = np.flatnonzero(net.status)
        f, t = net.f[on], net.t[on]
        yff, yft, ytf, ytt = (y[on] for y in net.branch_admittances)
        return cls(f, t, yff, yft, ytf, ytt, incidence(f, net.n_bus), incidence(t, net.n_bus))

    @property
    def n_branch(self) -> int:
        return self.f.size

    def flows(self, vf: Any, vt: Any, c: Any, s: Any, mul: Mul) -> tuple[Any, Any, Any, Any]:
        """(P_f, Q_f, P_t, Q_t) p.u. as expressions of the modelling tool; `mul(a, x)` is
        its elementwise product of a constant array and an expression."""
        yff, yft, ytf, ytt = self.yff, self.yft, self.ytf, self.ytt
        p_f = mul(yff.real, vf) + mul(yft.real, c) + mul(yft.imag, s)
        q_f = mul(-yff.imag, vf) + mul(yft.real, s) - mul(yft.imag, c)
        p_t = mul(ytt.real, vt) + mul(ytf.real, c) - mul(ytf.imag, s)
        q_t = mul(-ytt.imag, vt) - mul(ytf.real, s) - mul(ytf.imag, c)
        return p_f, q_f, p_t, q_t


def bus_shunts(net: Network) -> tuple[np.ndarray, np.ndarray]:
    """(gsh, bsh) per bus, p.u.: the bus shunt admittance from Gs/Bs (MW/MVAr at 1 p.u.)."""
    return net.gs_mw / net.base_mva, net.bs_mvar / net.base_mva


def ac_feasible(net: Network, pf: PowerFlowResult, s_fixed_pu: np.ndarray, slack_export: bool) -> np.ndarray:
    """Which AC power-flow solutions respect the OPF's constraints: converged, every |V|
    within [vmin, vmax] ± VOLTAGE_TOLERANCE and, when the slack may not export, slack
    P ≥ −SLACK_P_TOLERANCE MW. `pf` holds one snapshot or a batch (S, n_bus); `s_fixed_pu`
    the matching fixed injections (p.u.). Returns a bool per snapshot."""
    vm = np.atleast_2d(pf.vm)
    ok = np.atleast_1d(np.asarray(pf.converged, dtype=bool)).copy()
    with np.errstate(invalid="ignore"):
        ok &= np.all(vm >= net.vmin - VOLTAGE_TOLERANCE, axis=1) & np.all(vm <= net.vmax + VOLTAGE_TOLERANCE, axis=1)
        if not slack_export:
            fixed_at_slack = np.atleast_2d(s_fixed_pu)[:, net.slack].real * net.base_mva
            ok &= np.atleast_1d(pf.slack_s_mva.real) - fixed_at_slack >= -SLACK_P_TOLERANCE
    return ok


def diagnostics(rows: Iterable[dict]) -> dict[str, np.ndarray]:
    """Per-snapshot diagnostic dicts (same keys) → one array per key for `StrategyResult.extra`
    (bool, int64, object for strings, float otherwise)."""
    rows = list(rows)
    out: dict[str, np.ndarray] = {}
    for key in rows[0] if rows else ():
        values = [r[key] for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in values):
            out[key] = np.array(values, dtype=bool)
        elif all(isinstance(v, (int, np.integer)) for v in values):
            out[key] = np.array(values, dtype=np.int64)
        elif all(isinstance(v, str) for v in values):
            out[key] = np.array(values, dtype=object)
        else:
            out[key] = np.array(values, dtype=float)
    return out


def evaluated_result(strategy: str, k: float, scenario: Scenario, data: SnapshotData, q_pu: np.ndarray,
                     slack_export: bool, wall_ms: float, status: np.ndarray, lower_bound_kw: np.ndarray,
                     extra: dict[str, np.ndarray], power_flows: np.ndarray | int = 0) -> StrategyResult:
    """A formulation's result: setpoints `q_pu` (S, n_der) evaluated by the batched AC power
    flow, with extra["ac_feasible"] (the point meets every limit of the OPF, `ac_feasible`)
    and the scalar extra["slack_export"] (the option the limits were checked with)."""
    net = scenario.net
    q_mvar = np.asarray(q_pu, dtype=float).reshape(scenario.n_snapshots, len(net.ders)) * net.base_mva
    pf = solve_pf_batch(net, scenario.injections(q_mvar))
    extra = extra | {"ac_feasible": ac_feasible(net, pf, data.s_fixed, slack_export), "slack_export": slack_export}
    flows = np.asarray(power_flows, dtype=np.int64) + 1
    return StrategyResult.from_setpoints(strategy, k, scenario, q_mvar, wall_ms, power_flows=flows, pf=pf,
                                         status=status, lower_bound_kw=lower_bound_kw, extra=extra)
