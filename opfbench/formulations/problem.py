"""The OPF problem, written once; every formulation (`acopf`, `socp`) models it.

Per snapshot, per unit on `net.base_mva` (voltages p.u., powers p.u., squared
magnitudes p.u.²; results are converted to MVAr and kW at the boundary; injections
positive into the grid, DER Q positive = injected):

    minimize    branch losses (series and charging, what `PowerFlowResult.losses_kw` reports)
    over        Q of every DER (P fixed), the bus voltages
    subject to  power balance at every non-slack bus,
                |V_slack| = net.v_slack,  vmin ≤ |V| ≤ vmax at every other bus,
                −(1 − k)·Qmax(P) ≤ Q ≤ (1 − k)·Qmax(P) for every DER,
                slack P ≥ 0 when the slack may not export (`slack_export=False`,
                the paper's and pandapower's setup).

Every formulation writes the power balance through the same *bus mismatch*, the power a
bus pushes into its branches and shunt minus what it is given:

    mismatch_p[i] = Σ branch P leaving i + gsh_i·v_i − p_fixed_i
    mismatch_q[i] = Σ branch Q leaving i − bsh_i·v_i − q_fixed_i − (DER Q at i)

with v_i = |V_i|². `OpfProblem.balance` turns the two mismatch expressions into the
constraint rows (zero at every non-slack bus; at the slack bus the mismatch is what the
external grid injects, hence the slack rule), `OpfProblem.feasible` checks an AC
power-flow solution against the same limits. A formulation supplies only its network
model (how branch flows depend on its variables) and its objective expression.

Also here: the per-snapshot inputs (`snapshot_data`) and the π-model branch coefficients.
The status vocabulary is `opfbench.result`'s; the result assembly `formulations.evaluation`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from opfbench.capability import INVERTER_TAN_PHI_MAX, TAN_PHI_MAX, check_reserve
from opfbench.errors import NetworkError
from opfbench.network import DerFleet, Network
from opfbench.powerflow import PowerFlowResult
from opfbench.scenario import Scenario

VOLTAGE_TOLERANCE = 1e-6  # p.u.: a point is within limits up to this
SLACK_P_TOLERANCE = 1e-6  # MW: slack "does not export" up to this


def kw_per_pu(net: Network) -> float:
    """Factor from active power in p.u. on `net.base_mva` to kW."""
    return net.base_mva * 1e3


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


@dataclass(frozen=True)
class Row:
    """Constraint rows lo ≤ expr ≤ hi (elementwise; ±inf = no bound) of a formulation's
    own modelling tool; `name` says what they are."""

    name: str
    expr: Any
    lo: np.ndarray
    hi: np.ndarray


@dataclass(frozen=True, eq=False)
class OpfProblem:
    """The OPF problem on one network (see the module docstring), checked once.

    slack: the slack bus; others: every other bus (internal indices); vm_min / vm_max:
    |V| limits at `others` (p.u.); gsh / bsh: bus shunt conductance / susceptance (p.u.);
    der_at_bus: (n_bus, n_der) incidence summing DER Q onto buses; branches: the π model.
    """

    net: Network
    slack_export: bool
    others: np.ndarray
    vm_min: np.ndarray
    vm_max: np.ndarray
    gsh: np.ndarray
    bsh: np.ndarray
    der_at_bus: sp.csr_matrix
    branches: PiBranches

    @classmethod
    def of(cls, net: Network, slack_export: bool = True) -> "OpfProblem":
        """The problem of `net`; NetworkError for what the formulations do not model or
        inconsistent limits."""
        check_supported(net)
        others = np.flatnonzero(np.arange(net.n_bus) != net.slack)
        gsh, bsh = bus_shunts(net)
        return cls(
            net,
            bool(slack_export),
            others,
            net.vmin[others],
            net.vmax[others],
            gsh,
            bsh,
            incidence(net.der_bus, net.n_bus),
            PiBranches.of(net),
        )

    @property
    def slack(self) -> int:
        return self.net.slack

    @property
    def v_slack(self) -> float:
        return self.net.v_slack

    @property
    def kw_per_pu(self) -> float:
        return kw_per_pu(self.net)

    def balance(self, mismatch_p: Any, mismatch_q: Any, index: Callable[[Any, np.ndarray], Any]) -> list[Row]:
        """The power-balance rows: mismatch_p = mismatch_q = 0 at every non-slack bus and,
        when the slack may not export, slack P = mismatch_p[slack] ≥ 0. `index(expr, idx)`
        selects entries of an expression of the formulation's tool."""
        m = self.others.size
        rows = [
            Row("P balance", index(mismatch_p, self.others), np.zeros(m), np.zeros(m)),
            Row("Q balance", index(mismatch_q, self.others), np.zeros(m), np.zeros(m)),
        ]
        if not self.slack_export:
            rows.append(Row("slack P ≥ 0", index(mismatch_p, np.array([self.slack])), np.zeros(1), np.full(1, np.inf)))
        return rows

    def feasible(self, pf: PowerFlowResult, s_fixed_pu: np.ndarray) -> np.ndarray:
        """Which AC power-flow solutions meet the limits: converged, every |V| within
        [vmin, vmax] ± VOLTAGE_TOLERANCE and, when the slack may not export, slack
        P ≥ −SLACK_P_TOLERANCE MW. `pf` holds one snapshot or a batch (S, n_bus);
        `s_fixed_pu` the matching fixed injections (p.u.). Returns a bool per snapshot."""
        return ac_feasible(self.net, pf, s_fixed_pu, self.slack_export)


def check_supported(net: Network) -> None:
    """Refuse what the formulations do not model, and inconsistent limits, with the reason."""
    if net.pv_buses.size:
        ids = ", ".join(str(b) for b in net.bus_ids[net.pv_buses])
        raise NetworkError(f"{net.name}: the OPF formulations do not model voltage-controlled (PV) buses ({ids})")
    if np.any(net.der_bus == net.slack):
        raise NetworkError(f"{net.name}: a DER at the slack bus has no effect on the network; move it or drop it")
    bad = np.flatnonzero(~(np.isfinite(net.vmin) & np.isfinite(net.vmax) & (net.vmin >= 0) & (net.vmin <= net.vmax)))
    bad = bad[bad != net.slack]  # the slack's |V| is fixed at v_slack
    if bad.size:
        i = bad[0]
        raise NetworkError(
            f"{net.name}: bus {net.bus_ids[i]} has voltage limits vmin {net.vmin[i]:g} p.u., "
            f"vmax {net.vmax[i]:g} p.u.; the OPF needs 0 ≤ vmin ≤ vmax, both finite"
            + (f" ({bad.size} such buses)" if bad.size > 1 else "")
        )


@dataclass(frozen=True)
class SnapshotData:
    """The OPF inputs of every snapshot, per unit on the network's base.

    s_fixed (S, n_bus) complex: every injection the OPF does not decide — fixed
    generators + DER active power − load_scale·load (positive into the grid).
    q_limit (S, n_der) ≥ 0: usable (1 − k)·Qmax, or the scenario's own `q_limit_mvar`;
    each DER's Q lies in [−q_limit, q_limit].
    """

    s_fixed: np.ndarray
    q_limit: np.ndarray

    @property
    def n_snapshots(self) -> int:
        return self.s_fixed.shape[0]


def snapshot_data(scenario: Scenario, k: float) -> SnapshotData:
    """Per-unit inputs of `scenario` with reserve coefficient k (InputError unless one
    number in [0, 1]; the scenario's `q_limit_mvar`, where given, is the DER's limit)."""
    k = check_reserve(k)
    net = scenario.net
    check_supported(net)
    zero_q = np.zeros_like(scenario.der_p_mw)
    s_fixed = scenario.injections(zero_q) / net.base_mva
    q_limit = scenario.usable_q_mvar(k) / net.base_mva  # "Q at night" where the scenario says
    return SnapshotData(s_fixed, q_limit)


NO_LIMIT_PU = 1e3  # p.u.: the offset of a capability piece that does not apply (night, no such piece)
DFIG_SLOPE, DFIG_OFFSET = -5.0 / 6.0, 4.0 / 3.0  # the DFIG curve's falling piece, Qmax/P̄ = −5/6·P/P̄ + 4/3


@dataclass(frozen=True)
class PqCapability:
    """Every DER's P–Q capability written for an OPF that decides its active power too
    (`curtail`), per unit on the network's base, at reserve k: for each of two pieces j,
    |Q| ≤ slope[:, j]·P + offset_j (the offsets per snapshot: `CurtailData.offset`), and for
    the inverter-coupled units (`circle`) Q² + (share·P)² ≤ (share·S̄)² — `capability.qmax`
    at every P, scaled by share = 1 − k: PV 0.75·P and the S̄ circle, the inverter
    0.4843·|P| and the circle, the DFIG min(P̄, 4/3·P̄ − 5/6·P)."""

    slope: np.ndarray  # (n_der, 2)
    circle: np.ndarray  # (n_der,) bool
    share: float
    s_pu: np.ndarray  # (n_der,) S̄

    @classmethod
    def of(cls, net: DerFleet, k: float, base_mva: float | None = None) -> "PqCapability":
        """The capability of `net`'s DER at reserve k, per unit on `base_mva` (default the
        network's own base; a three-phase feeder has none: its models work in MW, base 1)."""
        share = 1.0 - check_reserve(k)
        kinds = np.asarray(net.der_kinds)
        slope = np.zeros((len(kinds), 2))
        slope[kinds == "PV", 0] = TAN_PHI_MAX
        slope[kinds == "inverter", 0] = INVERTER_TAN_PHI_MAX
        slope[kinds == "DFIG", 1] = DFIG_SLOPE
        base = base_mva if base_mva is not None else net.base_mva if isinstance(net, Network) else 1.0
        return cls(share * slope, kinds != "DFIG", share, net.der_s_mva / base)

    def rows(self, q: Any, p: Any, slope: Any, offset: Any, share: Any) -> list[Row]:
        """The capability as constraint rows of a modelling tool's expressions (CasADi,
        elementwise): |Q| ≤ slope_j·P + offset_j for both pieces j (`slope` and `offset`
        stacked piece by piece, `share` a scalar — the model's parameters), and
        Q² + (share·P)² ≤ (share·S̄)² for the inverter-coupled units."""
        n_der = self.s_pu.size
        out = []
        for j in range(2):
            reach = slope[j * n_der : (j + 1) * n_der] * p + offset[j * n_der : (j + 1) * n_der]
            out += [Row(f"Q ≤ piece {j}", q - reach, np.full(n_der, -np.inf), np.zeros(n_der))]
            out += [Row(f"−Q ≤ piece {j}", -q - reach, np.full(n_der, -np.inf), np.zeros(n_der))]
        c = np.flatnonzero(self.circle)
        if c.size:
            circle = q[c.tolist()] ** 2 + (share * p[c.tolist()]) ** 2 - share**2 * self.s_pu[c] ** 2
            out.append(Row("S̄ circle", circle, np.full(c.size, -np.inf), np.zeros(c.size)))
        return out


@dataclass(frozen=True)
class CurtailData:
    """The inputs of an OPF that may curtail, per snapshot, p.u.: `s_fixed` (S, n_bus) the
    injections it does not decide without the DER's active power; `p_avail` (S, n_der) the
    power each DER has; `p_low` (S, n_der) the least it may deliver, min(P, 0) (only output
    is curtailed); `offset` (S, n_der, 2) the capability pieces' offsets (`PqCapability`)."""

    s_fixed: np.ndarray
    p_avail: np.ndarray
    p_low: np.ndarray
    offset: np.ndarray

    @property
    def n_snapshots(self) -> int:
        return self.s_fixed.shape[0]


def curtail_data(scenario: Scenario, k: float) -> CurtailData:
    """`CurtailData` of `scenario` at reserve k: the PV and inverter units' power-factor piece
    lapses at the "Q at night" snapshots; an inverter drawing its own consumption (P < 0,
    held there) keeps |Q| ≤ 0.4843·|P| through its offset."""
    net = scenario.net
    base = net.base_mva
    p_avail = scenario.der_p_mw / base
    s_fixed = scenario.injections(np.zeros_like(p_avail), np.zeros_like(p_avail)) / base
    return CurtailData(s_fixed, p_avail, np.minimum(p_avail, 0.0), capability_offsets(scenario, k, base))


def capability_offsets(scenario: Scenario, k: float, base_mva: float) -> np.ndarray:
    """(S, n_der, 2) the offsets of the capability pieces (`PqCapability`) of `scenario`'s
    DER at reserve k, p.u. on `base_mva` (`curtail_data`)."""
    share = 1.0 - check_reserve(k)
    net = scenario.net
    p_avail = scenario.der_p_mw / base_mva
    kinds = np.asarray(net.der_kinds)
    n, m = p_avail.shape
    offset = np.full((n, m, 2), NO_LIMIT_PU)
    night = scenario.night_q()
    night = np.asarray(night) if isinstance(night, np.ndarray) else np.zeros((n, m), dtype=bool)
    inverter = kinds == "inverter"
    own = share * INVERTER_TAN_PHI_MAX * np.maximum(-p_avail, 0.0) * 2.0  # q ≤ a·P + 2a·|P| = a·|P| for P < 0
    offset[:, :, 0] = np.where(kinds == "DFIG", share * net.der_rating_mw / base_mva, np.where(inverter, own, 0.0))
    offset[:, :, 0] = np.where(night & (kinds != "DFIG"), NO_LIMIT_PU, offset[:, :, 0])
    offset[:, kinds == "DFIG", 1] = share * DFIG_OFFSET * net.der_rating_mw[kinds == "DFIG"] / base_mva
    return offset


def bus_shunts(net: Network) -> tuple[np.ndarray, np.ndarray]:
    """(gsh, bsh) per bus, p.u.: the bus shunt admittance from Gs/Bs (MW/MVAr at 1 p.u.)."""
    return net.gs_mw / net.base_mva, net.bs_mvar / net.base_mva


def ac_feasible(net: Network, pf: PowerFlowResult, s_fixed_pu: np.ndarray, slack_export: bool) -> np.ndarray:
    """`OpfProblem.feasible` for any network (also one the formulations cannot model)."""
    vm = np.atleast_2d(pf.vm)
    ok = np.atleast_1d(np.asarray(pf.converged, dtype=bool)).copy()
    with np.errstate(invalid="ignore"):
        ok &= np.all(vm >= net.vmin - VOLTAGE_TOLERANCE, axis=1) & np.all(vm <= net.vmax + VOLTAGE_TOLERANCE, axis=1)
        if not slack_export:
            fixed_at_slack = np.atleast_2d(s_fixed_pu)[:, net.slack].real * net.base_mva
            ok &= np.atleast_1d(slack_p_mw(net, pf)) - fixed_at_slack >= -SLACK_P_TOLERANCE
    return ok


def slack_p_mw(net: Network, pf: PowerFlowResult) -> np.ndarray:
    """Active power the slack bus injects into the grid (MW): the P flowing into its
    in-service branches plus its shunt's — from branch flows, without the n×n Y-bus."""
    at_slack_f, at_slack_t = net.f == net.slack, net.t == net.slack
    vm2 = np.abs(pf.v[..., net.slack]) ** 2
    return (
        pf.sf_mva.real[..., at_slack_f].sum(axis=-1) + pf.st_mva.real[..., at_slack_t].sum(axis=-1) + net.gs_mw[net.slack] * vm2
    )
