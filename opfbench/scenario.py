"""Operating points a strategy is asked to handle: S snapshots of load and DER output.

Loads are given one of two ways: `load_scale` (S,) × the case's nominal loads (every load
follows one profile, the special case the shipped cases use), or every load element's own
P and Q (S, n_load) MW/MVAr (`Scenario.from_series`: a real grid's per-load profiles).
DER active power is given in MW per unit (P^C, the current output) and optionally a
forecast P^F for Algorithm 3. Everything downstream reads the loads through the accessors
`injections`, `load_q_at_der_mvar`, `load_p_at_der_mw` (each DER's share of its bus's
load: `Network.der_share`) and `bus_load_mva`, and the
capability through `qmax_mvar`, so both forms run every strategy and formulation alike.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, Generic, TypeVar

import numpy as np

from opfbench.capability import qmax
from opfbench.errors import InputError
from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network
from opfbench.powerflow import PowerFlowResult, bus_injections, solve_pf_batch
from opfbench.powerflow.multiphase import PhaseFlowResult, solve_phase_flow

if TYPE_CHECKING:
    import pandas as pd

    from opfbench.io.case import Case


NetT = TypeVar("NetT", bound=Network | PhaseNetwork)
"""A scenario's network: balanced (bus level) or three-phase (node level)."""


@dataclass(frozen=True, eq=False)
class Scenario(Generic[NetT]):
    """S snapshots on one network. Arrays: load_scale (S,) — or None when the per-load
    load_p_mw and load_q_mvar (S, n_load) MW/MVAr are given instead —, der_p_mw (S, n_der)
    MW, der_p_forecast_mw (S, n_der) MW or None. A single snapshot may give der_p_mw as
    (n_der,). The constructor copies its inputs into read-only arrays and checks shapes
    against the network (a transposed array is an error, never reshaped), that values
    are real and finite, load_scale ≥ 0 and P ≤ rating with P ≥ 0 (PV, DFIG) or P ≥ −S̄
    (an inverter unit's own consumption) — for the forecast P^F too: a forecast outside the
    plant's range is refused, never clipped here (a caller that turns a forecaster's output
    into P^F clips it explicitly). Per-load P and Q may have either sign (negative = the
    element injects, e.g. SimBench's capacitive load Q). pv_night_q (S,) bool or None:
    snapshots where the solar units have the S-limited "Q at night" capability (night mode
    "connected-q"). q_limit_mvar (S, n_der) MVAr or None: the reactive limit |Q| ≤
    q_limit_mvar a formulation's DER use instead of (1 − k)·Qmax(P^C) — the capability a
    rule's setpoints used, which its frontier is computed at (`formulations.frontier`);
    each within [0, Qmax(P^C)] (the local rules keep their own limits)."""

    net: NetT
    load_scale: np.ndarray | None
    der_p_mw: np.ndarray
    der_p_forecast_mw: np.ndarray | None = None
    pv_night_q: np.ndarray | None = None
    load_p_mw: np.ndarray | None = None
    load_q_mvar: np.ndarray | None = None
    q_limit_mvar: np.ndarray | None = None

    def __post_init__(self) -> None:
        _check_net(self.net)
        n_der = len(self.net.ders)
        if self.load_scale is None:
            n_snap = self._check_loads()
        else:
            if self.load_p_mw is not None or self.load_q_mvar is not None:
                raise InputError("scenario: give either load_scale or the per-load load_p_mw and load_q_mvar, not both")
            ls = _real_array("load_scale", self.load_scale)
            if ls.ndim > 1:
                raise InputError(f"scenario: load_scale must be a number or a 1-D array (S,), got shape {ls.shape}")
            ls = np.atleast_1d(ls)
            if ls.size == 0:
                raise InputError("scenario: no snapshot (load_scale is empty)")
            _check_finite("load_scale", ls)
            if np.any(ls < 0):
                raise InputError(f"scenario: load_scale must be ≥ 0, got {ls.min()} at index {int(np.argmin(ls))}")
            object.__setattr__(self, "load_scale", _frozen(ls))
            n_snap = ls.shape[0]
        self._check_total_load()
        p = _der_array("der_p_mw", self.der_p_mw, n_snap, n_der)
        _check_finite("der_p_mw", p)
        self._check_range("der_p_mw", p)
        object.__setattr__(self, "der_p_mw", _frozen(p))
        if self.der_p_forecast_mw is not None:
            pf = _der_array("der_p_forecast_mw", self.der_p_forecast_mw, n_snap, n_der)
            _check_finite("der_p_forecast_mw", pf)
            self._check_range("der_p_forecast_mw", pf)
            object.__setattr__(self, "der_p_forecast_mw", _frozen(pf))
        if self.pv_night_q is not None:
            raw = np.array(self.pv_night_q)
            if raw.dtype != bool and not (raw.dtype.kind in "iu" and np.isin(raw, (0, 1)).all()):
                raise InputError(f"scenario: pv_night_q must be true/false per snapshot, got {raw.dtype} values")
            mask = raw.astype(bool)
            if mask.shape != (n_snap,):
                raise InputError(f"scenario: pv_night_q must have shape (S,) = ({n_snap},), got {mask.shape}")
            object.__setattr__(self, "pv_night_q", _frozen(mask))
        if self.q_limit_mvar is not None:
            limit = _der_array("q_limit_mvar", self.q_limit_mvar, n_snap, n_der)
            _check_finite("q_limit_mvar", limit)
            if np.any(limit < 0) or np.any(limit > self.qmax_mvar() * (1 + 1e-9) + 1e-12):
                raise InputError("scenario: q_limit_mvar must lie within [0, Qmax(P)] MVAr, the DER's capability")
            object.__setattr__(self, "q_limit_mvar", _frozen(limit))

    def _check_loads(self) -> int:
        """Per-load P and Q: both given, (S, n_load), real and finite; returns S."""
        if self.load_p_mw is None or self.load_q_mvar is None:
            raise InputError("scenario: without load_scale both load_p_mw and load_q_mvar (S, n_load) are needed")
        n_load = self.net.n_load
        arrays = {}
        for label in ("load_p_mw", "load_q_mvar"):
            arr = _real_array(label, getattr(self, label))
            if arr.ndim != 2 or arr.shape[1] != n_load:
                raise InputError(
                    f"scenario: {label} must have shape (S, n_load) = (S, {n_load}) (n_load from the network), got {arr.shape}"
                )
            _check_finite(label, arr)
            arrays[label] = arr
        if arrays["load_p_mw"].shape[0] == 0:
            raise InputError("scenario: no snapshot (load_p_mw is empty)")
        if arrays["load_p_mw"].shape != arrays["load_q_mvar"].shape:
            raise InputError(
                f"scenario: load_p_mw {arrays['load_p_mw'].shape} and load_q_mvar {arrays['load_q_mvar'].shape} differ in shape"
            )
        for label, arr in arrays.items():
            object.__setattr__(self, label, _frozen(arr))
        return arrays["load_p_mw"].shape[0]

    def _check_total_load(self) -> None:
        """Each snapshot's total load (Σ|P| + Σ|Q|) is a finite number of MW: every load
        finite does not make their sum (or load_scale × the nominal loads) finite."""
        with np.errstate(over="ignore", invalid="ignore"):
            if self.load_scale is None:
                assert self.load_p_mw is not None and self.load_q_mvar is not None
                total = np.abs(self.load_p_mw).sum(axis=1) + np.abs(self.load_q_mvar).sum(axis=1)
            else:
                total = self.load_scale * (np.abs(self.net.load_p_mw).sum() + np.abs(self.net.load_q_mvar).sum())
        if not np.isfinite(total).all():
            s = int(np.flatnonzero(~np.isfinite(total))[0])
            scale = "" if self.load_scale is None else f" (load_scale {self.load_scale[s]:g} × the nominal loads)"
            raise InputError(f"scenario: the total load of snapshot {s}{scale} is not a finite number of MW")

    @property
    def per_load(self) -> bool:
        """True when every load element has its own P and Q (no load_scale)."""
        return self.load_scale is None

    def same_data(self, other: "Scenario") -> bool:
        """The same network object and the same snapshots — loads, DER P, forecast and the
        "Q at night" mask (a mask set nowhere counts as none) — so that every strategy, a
        deterministic function of these, gives the same result on both."""

        def night_q(s: Scenario) -> np.ndarray | None:
            return s.pv_night_q if s.pv_night_q is not None and s.pv_night_q.any() else None

        def equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
            return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))

        return (
            self.net is other.net
            and equal(self.load_scale, other.load_scale)
            and equal(self.load_p_mw, other.load_p_mw)
            and equal(self.load_q_mvar, other.load_q_mvar)
            and equal(self.der_p_mw, other.der_p_mw)
            and equal(self.der_p_forecast_mw, other.der_p_forecast_mw)
            and equal(night_q(self), night_q(other))
            and equal(self.q_limit_mvar, other.q_limit_mvar)
        )

    def same_rows(self, other: "Scenario") -> np.ndarray:
        """(S,) bool: snapshot i carries the same data here and in `other` (the same network
        object and number of snapshots) — loads, DER P, forecast and "Q at night" — so a
        snapshot-wise strategy (`StrategySpec.snapshot_wise`) gives both the same result."""
        n = self.n_snapshots
        if self.net is not other.net or other.n_snapshots != n:
            return np.zeros(n, dtype=bool)

        def equal(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray:
            if a is None or b is None:
                return np.full(n, a is None and b is None)
            return (a == b).reshape(n, -1).all(axis=1)

        def night_q(s: Scenario) -> np.ndarray:
            return np.zeros(n, dtype=bool) if s.pv_night_q is None else s.pv_night_q

        return (
            equal(self.load_scale, other.load_scale)
            & equal(self.load_p_mw, other.load_p_mw)
            & equal(self.load_q_mvar, other.load_q_mvar)
            & equal(self.der_p_mw, other.der_p_mw)
            & equal(self.der_p_forecast_mw, other.der_p_forecast_mw)
            & (night_q(self) == night_q(other))
            & equal(self.q_limit_mvar, other.q_limit_mvar)
        )

    @classmethod
    def union(cls, parts: "list[tuple[Scenario, np.ndarray]]") -> "Scenario":
        """One scenario of the snapshots `rows` of each (scenario, rows) in turn: the same
        network, loads given the same way, all with a forecast or none."""
        first = parts[0][0]
        if any(s.net is not first.net or s.per_load != first.per_load for s, _ in parts):
            raise InputError("scenario union: every part needs the same network and the same kind of loads")
        if len({s.der_p_forecast_mw is None for s, _ in parts}) > 1:
            raise InputError("scenario union: every part needs a forecast, or none")
        if any(s.q_limit_mvar is not None for s, _ in parts):
            raise InputError("scenario union: a part with its own reactive limit (q_limit_mvar) is not shared")

        def stacked(name: str) -> np.ndarray | None:
            arrays = [getattr(s, name) for s, _ in parts]
            return None if arrays[0] is None else np.concatenate([a[rows] for a, (_, rows) in zip(arrays, parts, strict=True)])

        masks = [np.zeros(s.n_snapshots, dtype=bool) if s.pv_night_q is None else s.pv_night_q for s, _ in parts]
        mask = np.concatenate([m[rows] for m, (_, rows) in zip(masks, parts, strict=True)])
        der_p = np.concatenate([s.der_p_mw[rows] for s, rows in parts])
        return cls(
            first.net,
            stacked("load_scale"),
            der_p,
            stacked("der_p_forecast_mw"),
            mask if mask.any() else None,
            stacked("load_p_mw"),
            stacked("load_q_mvar"),
        )

    def _check_range(self, label: str, p: np.ndarray) -> None:
        """P ≤ rating (MW) per DER, up to round-off, and P ≥ 0 — or P ≥ −S̄ for an inverter
        unit, which may draw its own consumption."""
        net = self.net
        rating = net.der_rating_mw
        floor = np.where(np.array([kind == "inverter" for kind in net.der_kinds], dtype=bool), -net.der_s_mva, 0.0)
        bad = (p < floor) | (p > rating * (1 + 1e-9))
        if np.any(bad):
            s, d = np.argwhere(bad)[0]
            low = "0" if floor[d] == 0 else "−S̄"
            raise InputError(
                f"scenario: {label} must lie in [{low}, rating] MW; snapshot {s}, DER {d} "
                f"(bus {net.bus_ids[net.ders[d].bus]}): {p[s, d]:.6g} MW, rating {rating[d]:.6g} MW"
            )

    @classmethod
    def snapshot(
        cls, net: Network | PhaseNetwork, load_scale: float = 1.0, der_scale: float = 0.8, forecast_der_scale: float | None = None
    ) -> "Scenario":
        """One snapshot: every DER at `der_scale` × rating (and optionally a forecast)."""
        _check_net(net)
        for label, value in (("der_scale", der_scale), ("forecast_der_scale", forecast_der_scale)):
            if value is not None and not 0 <= value <= 1:
                raise InputError(f"{label} is a fraction of rating and must lie in [0, 1], got {value}")
        rating = net.der_rating_mw
        forecast = None if forecast_der_scale is None else np.array([forecast_der_scale * rating])
        return Scenario(net, np.array([load_scale]), np.array([der_scale * rating]), forecast)

    @classmethod
    def from_series(
        cls,
        net: Network | PhaseNetwork,
        load_p_mw: np.ndarray,
        load_q_mvar: np.ndarray,
        der_p_mw: np.ndarray,
        der_p_forecast_mw: np.ndarray | None = None,
    ) -> "Scenario":
        """Snapshots of every load's own P and Q (S, n_load) and every DER's P (S, n_der)."""
        return Scenario(net, None, der_p_mw, der_p_forecast_mw, load_p_mw=load_p_mw, load_q_mvar=load_q_mvar)

    @classmethod
    def of_case(cls, case: Case, times: pd.DatetimeIndex | None = None) -> "Scenario":
        """A case's stored operating point as one snapshot (`times` None: per-load P and Q,
        DER P as stored), or its own series at the tz-aware instants `times`."""
        if times is None:
            if case.stored is None:
                raise InputError(f"{case.spec}: the case stores no per-element operating point")
            p, q, der_p, _ = case.stored
            return cls.from_series(case.network, p[None, :], q[None, :], der_p[None, :])
        if case.series is None:
            raise InputError(f"{case.spec}: the case has no time series of its own")
        load_p, load_q, der_p = case.series.rows(times)
        return cls.from_series(case.network, load_p, load_q, der_p)

    @property
    def n_snapshots(self) -> int:
        return self.der_p_mw.shape[0]

    @cached_property
    def _bus_load(self) -> np.ndarray:
        """(S, n_bus) complex MVA: the per-load P + jQ summed onto the buses."""
        assert self.load_p_mw is not None and self.load_q_mvar is not None and isinstance(self.net, Network)
        out = (self.net.load_incidence @ (self.load_p_mw + 1j * self.load_q_mvar).T).T
        out = np.ascontiguousarray(out)
        out.setflags(write=False)
        return out

    def bus_load_mva(self) -> np.ndarray:
        """Load per bus (S, n_bus) complex MVA (P + jQ, positive = consumed)."""
        if self.load_scale is None:
            return self._bus_load
        return self.load_scale[:, None] * (self.net.load_p_mw + 1j * self.net.load_q_mvar)[None, :]

    @property
    def three_phase(self) -> bool:
        """True on a three-phase feeder (`PhaseNetwork`: node-level loads and DER)."""
        return isinstance(self.net, PhaseNetwork)

    def element_loads(self) -> tuple[np.ndarray, np.ndarray]:
        """(load P (S, n_load) MW, load Q (S, n_load) MVAr) of every load element (a
        three-phase feeder's loads that keep their nominal keep it: `PhaseNetwork.loads_at`)."""
        if self.load_scale is None:
            assert self.load_p_mw is not None and self.load_q_mvar is not None
            return self.load_p_mw, self.load_q_mvar
        if isinstance(self.net, PhaseNetwork):
            return self.net.loads_at(self.load_scale)
        return self.load_scale[:, None] * self.net.load_p_mw[None, :], self.load_scale[:, None] * self.net.load_q_mvar[None, :]

    def flow(self, der_q_mvar: np.ndarray, der_p_mw: np.ndarray | None = None) -> PowerFlowResult | PhaseFlowResult:
        """The batched AC power flow of every snapshot with the DER at reactive setpoints
        (S, n_der) MVAr and at P^C (or `der_p_mw`): bus-level on a balanced network, node
        level on a three-phase feeder."""
        if isinstance(self.net, PhaseNetwork):
            p = self.der_p_mw if der_p_mw is None else der_p_mw
            return solve_phase_flow(self.net, *self.element_loads(), p, der_q_mvar)
        return solve_pf_batch(self.net, self.injections(der_q_mvar, der_p_mw))

    def injections(self, der_q_mvar: np.ndarray, der_p_mw: np.ndarray | None = None) -> np.ndarray:
        """Bus injections (S, n_bus) complex MW for DER reactive setpoints (S, n_der) MVAr,
        with the DER at their available power P^C, or at `der_p_mw` (S, n_der) MW where a
        rule curtails."""
        p = self.der_p_mw if der_p_mw is None else der_p_mw
        net = self.net
        if not isinstance(net, Network):
            raise InputError(f"{net.name}: bus injections are a balanced network's (a three-phase feeder: `flow`)")
        if self.load_scale is None:
            return bus_injections(net, p, der_q_mvar, bus_load_mva=self._bus_load)
        return bus_injections(net, p, der_q_mvar, self.load_scale)

    def load_q_at_der_mvar(self) -> np.ndarray:
        """Each DER's share of the reactive load at its own bus (S, n_der) MVAr — what LLMA
        measures: the bus's load × `Network.der_share` (S̄ / Σ S̄ of the DER at that bus,
        1 for a DER alone), so the units at one bus compensate its load once."""
        return self._at_der(reactive=True)

    def load_p_at_der_mw(self) -> np.ndarray:
        """Each DER's share of the active load at its own bus (S, n_der) MW (shared as
        `load_q_at_der_mvar`)."""
        return self._at_der(reactive=False)

    def _at_der(self, reactive: bool) -> np.ndarray:
        """(S, n_der): the bus load's Q (`reactive`) or P (per-load form, or load_scale × the
        nominal) at each DER's bus, × its share of the bus; on a three-phase feeder the load
        on the DER's phases (`PhaseNetwork.der_load_weights`)."""
        net = self.net
        if isinstance(net, PhaseNetwork):
            loads = self.element_loads()[1 if reactive else 0]
            return np.ascontiguousarray((net.der_load_weights @ loads.T).T)
        if self.load_scale is None:
            part = self._bus_load.imag if reactive else self._bus_load.real
            return np.ascontiguousarray(part[:, net.der_bus] * net.der_share)
        nominal = net.load_q_mvar if reactive else net.load_p_mw
        return self.load_scale[:, None] * nominal[net.der_bus][None, :] * net.der_share

    @classmethod
    def from_profiles(
        cls,
        net: Network | PhaseNetwork,
        load_pu: np.ndarray,
        pv_pu: np.ndarray,
        wind_pu: np.ndarray,
        forecast_pv_pu: np.ndarray | None = None,
        forecast_wind_pu: np.ndarray | None = None,
    ) -> "Scenario":
        """Snapshots from per-unit profiles (S,): loads follow `load_pu` × nominal load;
        solar units `pv_pu` × rating; every other unit (DFIG, wind, …) `wind_pu` × rating
        (the mapping rule of `opfbench.data.profiles`). Forecast profiles, when given, set
        P^F the same way."""
        is_pv = net.der_solar
        load = _real_array("load_pu", load_pu)
        if load.ndim != 1:
            raise InputError(f"scenario: load_pu must be a 1-D profile (S,), got shape {load.shape}")
        _check_finite("load_pu", load)

        def profile(label: str, value: np.ndarray) -> np.ndarray:
            arr = _real_array(label, value)
            if arr.shape != load.shape:
                raise InputError(f"scenario: {label} must have the shape of load_pu {load.shape}, got {arr.shape}")
            _check_finite(label, arr)
            return arr

        def der_mw(pv: np.ndarray, wind: np.ndarray, prefix: str = "") -> np.ndarray:
            pv, wind = profile(f"{prefix}pv_pu", pv), profile(f"{prefix}wind_pu", wind)
            return np.where(is_pv, pv[:, None], wind[:, None]) * net.der_rating_mw

        forecast = None
        if forecast_pv_pu is not None or forecast_wind_pu is not None:
            forecast = der_mw(
                pv_pu if forecast_pv_pu is None else forecast_pv_pu,
                wind_pu if forecast_wind_pu is None else forecast_wind_pu,
                "forecast_",
            )
        return Scenario(net, load, der_mw(pv_pu, wind_pu), forecast)

    def take(self, rows: np.ndarray | slice) -> "Scenario":
        """The sub-scenario of some snapshots."""

        def part(arr: np.ndarray | None) -> np.ndarray | None:
            return None if arr is None else arr[rows]

        return Scenario(
            self.net,
            part(self.load_scale),
            self.der_p_mw[rows],
            part(self.der_p_forecast_mw),
            part(self.pv_night_q),
            part(self.load_p_mw),
            part(self.load_q_mvar),
            part(self.q_limit_mvar),
        )

    def without_forecast(self) -> "Scenario":
        """The same snapshots with no forecast P^F (and no "Q at night" mask)."""
        return Scenario(self.net, self.load_scale, self.der_p_mw, load_p_mw=self.load_p_mw, load_q_mvar=self.load_q_mvar)

    # ----- "Q at night" (night mode connected-q) -------------------------------------------
    def with_night_q(self, mask: np.ndarray) -> "Scenario":
        """This scenario with the solar units S-limited (|Q| ≤ √(S̄² − P²), no PF limit) at
        the snapshots where `mask` (S,) is True."""
        return replace(self, pv_night_q=mask)

    def night_q(self) -> np.ndarray | bool:
        """(S, n_der) where the solar units have the "Q at night" capability, or False
        (nowhere)."""
        if self.pv_night_q is None or not self.pv_night_q.any():
            return False
        return self.pv_night_q[:, None] & self.net.der_solar[None, :]

    def usable_q_mvar(self, k: float) -> np.ndarray:
        """(S, n_der) MVAr: the |Q| a formulation's DER may use at reserve k — `q_limit_mvar`
        where given, else (1 − k)·Qmax(P^C)."""
        return (1.0 - k) * self.qmax_mvar() if self.q_limit_mvar is None else np.array(self.q_limit_mvar)

    def qmax_mvar(self, p_mw: np.ndarray | None = None) -> np.ndarray:
        """(S, n_der) physical Qmax at active power `p_mw` (default P^C), MVAr, with the
        "Q at night" capability for the solar units at the `pv_night_q` snapshots."""
        p = self.der_p_mw if p_mw is None else p_mw
        net = self.net
        night = self.night_q()
        if night is False:
            return qmax(net.der_kinds, p, net.der_rating_mw, net.der_s_mva)
        return qmax(net.der_kinds, p, net.der_rating_mw, net.der_s_mva, night_q=night)


def _check_net(net: object) -> None:
    if not isinstance(net, (Network, PhaseNetwork)):
        raise InputError(
            f"scenario: net must be a Network or a PhaseNetwork (e.g. opfbench.io.load_network('paper33')), got {type(net).__name__}"
        )


def _real_array(label: str, value: object) -> np.ndarray:
    """A float copy of `value`; complex or non-numeric input is an error (never truncated)."""
    try:
        arr = np.array(value)
    except ValueError:  # ragged nested lists
        raise InputError(f"scenario: {label} is not a regular array (rows of different lengths)") from None
    if np.iscomplexobj(arr):
        raise InputError(f"scenario: {label} must be real, got complex values")
    if arr.dtype.kind not in "iuf":  # text ('1' would convert), true/false, objects
        raise InputError(f"scenario: {label} must be numeric, got {arr.dtype} values")
    return np.array(arr, dtype=float)


def _der_array(label: str, value: object, n_snap: int, n_der: int) -> np.ndarray:
    """`value` as (S, n_der); (n_der,) is accepted for a single snapshot."""
    arr = _real_array(label, value)
    if arr.ndim == 1 and n_snap == 1 and arr.shape[0] == n_der:
        arr = arr[None, :]
    if arr.shape != (n_snap, n_der):
        raise InputError(
            f"scenario: {label} must have shape (S, n_der) = ({n_snap}, {n_der}) "
            f"(S from load_scale, n_der from the network), got {arr.shape}"
        )
    return arr


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


def _check_finite(label: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"scenario: {label} has NaN or inf at index {tuple(int(i) for i in bad)}")
