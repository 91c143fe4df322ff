"""Operating points a strategy is asked to handle: S snapshots of load and DER output.

Loads follow `load_scale` × the case's nominal loads; DER active power is given in MW
per unit (P^C, the current output) and optionally a forecast P^F for Algorithm 3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.capability import qmax
from opfbench.errors import InputError
from opfbench.network import Network
from opfbench.powerflow import bus_injections


@dataclass(frozen=True, eq=False)
class Scenario:
    """S snapshots on one network. Arrays: load_scale (S,), der_p_mw (S, n_der) MW,
    der_p_forecast_mw (S, n_der) MW or None. A single snapshot may give der_p_mw as
    (n_der,). The constructor copies its inputs into read-only arrays and checks shapes
    against the network (a transposed array is an error, never reshaped), that values
    are real and finite, loads ≥ 0 and 0 ≤ P ≤ rating — for the forecast P^F too: a
    forecast outside the plant's range is refused, never clipped here (a caller that
    turns a forecaster's output into P^F clips it explicitly). pv_night_q (S,) bool or None:
    snapshots where PV units have the S-limited "Q at night" capability (night mode
    "connected-q")."""

    net: Network
    load_scale: np.ndarray
    der_p_mw: np.ndarray
    der_p_forecast_mw: np.ndarray | None = None
    pv_night_q: np.ndarray | None = None

    def __post_init__(self) -> None:
        n_der = len(self.net.ders)
        ls = _real_array("load_scale", self.load_scale)
        if ls.ndim > 1:
            raise InputError(f"scenario: load_scale must be a number or a 1-D array (S,), got shape {ls.shape}")
        ls = np.atleast_1d(ls)
        p = _der_array("der_p_mw", self.der_p_mw, ls.shape[0], n_der)
        _check_finite("load_scale", ls)
        _check_finite("der_p_mw", p)
        if np.any(ls < 0):
            raise InputError(f"scenario: load_scale must be ≥ 0, got {ls.min()} at index {int(np.argmin(ls))}")
        self._check_range("der_p_mw", p)
        object.__setattr__(self, "load_scale", _frozen(ls))
        object.__setattr__(self, "der_p_mw", _frozen(p))
        if self.der_p_forecast_mw is not None:
            pf = _der_array("der_p_forecast_mw", self.der_p_forecast_mw, ls.shape[0], n_der)
            _check_finite("der_p_forecast_mw", pf)
            self._check_range("der_p_forecast_mw", pf)
            object.__setattr__(self, "der_p_forecast_mw", _frozen(pf))
        if self.pv_night_q is not None:
            mask = np.array(self.pv_night_q, dtype=bool)
            if mask.shape != ls.shape:
                raise InputError(f"scenario: pv_night_q must have shape (S,) = {ls.shape}, got {mask.shape}")
            object.__setattr__(self, "pv_night_q", _frozen(mask))

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
            and equal(self.der_p_mw, other.der_p_mw)
            and equal(self.der_p_forecast_mw, other.der_p_forecast_mw)
            and equal(night_q(self), night_q(other))
        )

    def _check_range(self, label: str, p: np.ndarray) -> None:
        """0 ≤ P ≤ rating (MW) per DER, up to round-off."""
        rating = self.net.der_rating_mw
        bad = (p < 0) | (p > rating * (1 + 1e-9))
        if np.any(bad):
            s, d = np.argwhere(bad)[0]
            raise InputError(
                f"scenario: {label} must lie in [0, rating] MW; snapshot {s}, DER {d} "
                f"(bus {self.net.bus_ids[self.net.ders[d].bus]}): {p[s, d]:.6g} MW, rating {rating[d]:.6g} MW"
            )

    @classmethod
    def snapshot(
        cls, net: Network, load_scale: float = 1.0, der_scale: float = 0.8, forecast_der_scale: float | None = None
    ) -> "Scenario":
        """One snapshot: every DER at `der_scale` × rating (and optionally a forecast)."""
        for label, value in (("der_scale", der_scale), ("forecast_der_scale", forecast_der_scale)):
            if value is not None and not 0 <= value <= 1:
                raise InputError(f"{label} is a fraction of rating and must lie in [0, 1], got {value}")
        rating = net.der_rating_mw
        forecast = None if forecast_der_scale is None else np.array([forecast_der_scale * rating])
        return cls(net, np.array([load_scale]), np.array([der_scale * rating]), forecast)

    @property
    def n_snapshots(self) -> int:
        return self.load_scale.shape[0]

    def injections(self, der_q_mvar: np.ndarray) -> np.ndarray:
        """Bus injections (S, n_bus) complex MW for DER reactive setpoints (S, n_der) MVAr."""
        return bus_injections(self.net, self.der_p_mw, der_q_mvar, self.load_scale)

    def load_q_at_der_mvar(self) -> np.ndarray:
        """Reactive load at each DER's own bus (S, n_der) MVAr — what LLMA measures."""
        return self.load_scale[:, None] * self.net.load_q_mvar[self.net.der_bus][None, :]

    def load_p_at_der_mw(self) -> np.ndarray:
        """Active load at each DER's own bus (S, n_der) MW — what a DER's meter sees of it."""
        return self.load_scale[:, None] * self.net.load_p_mw[self.net.der_bus][None, :]

    @classmethod
    def from_profiles(
        cls,
        net: Network,
        load_pu: np.ndarray,
        pv_pu: np.ndarray,
        wind_pu: np.ndarray,
        forecast_pv_pu: np.ndarray | None = None,
        forecast_wind_pu: np.ndarray | None = None,
    ) -> "Scenario":
        """Snapshots from per-unit profiles (S,): loads follow `load_pu` × nominal load;
        PV units `pv_pu` × rating; DFIG units `wind_pu` × rating (the mapping rule of
        `opfbench.data.profiles`). Forecast profiles, when given, set P^F the same way."""
        is_pv = np.array([kind == "PV" for kind in net.der_kinds])
        load = _real_array("load_pu", load_pu)
        if load.ndim != 1:
            raise InputError(f"scenario: load_pu must be a 1-D profile (S,), got shape {load.shape}")

        def profile(label: str, value: np.ndarray) -> np.ndarray:
            arr = _real_array(label, value)
            if arr.shape != load.shape:
                raise InputError(f"scenario: {label} must have the shape of load_pu {load.shape}, got {arr.shape}")
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
        return cls(net, load, der_mw(pv_pu, wind_pu), forecast)

    def take(self, rows: np.ndarray | slice) -> "Scenario":
        """The sub-scenario of some snapshots."""
        fc = None if self.der_p_forecast_mw is None else self.der_p_forecast_mw[rows]
        night_q = None if self.pv_night_q is None else self.pv_night_q[rows]
        return Scenario(self.net, self.load_scale[rows], self.der_p_mw[rows], fc, night_q)

    # ----- "Q at night" (night mode connected-q) -------------------------------------------
    def with_night_q(self, mask: np.ndarray) -> "Scenario":
        """This scenario with PV units S-limited (|Q| ≤ √(S̄² − P²), no PF limit) at the
        snapshots where `mask` (S,) is True."""
        return Scenario(self.net, self.load_scale, self.der_p_mw, self.der_p_forecast_mw, mask)

    def qmax_mvar(self, p_mw: np.ndarray | None = None) -> np.ndarray:
        """(S, n_der) physical Qmax at active power `p_mw` (default P^C), MVAr, with the
        "Q at night" capability for PV units at the `pv_night_q` snapshots."""
        p = self.der_p_mw if p_mw is None else p_mw
        kinds, rating = self.net.der_kinds, self.net.der_rating_mw
        day = qmax(kinds, p, rating)
        if self.pv_night_q is None or not self.pv_night_q.any():
            return day
        return np.where(self.pv_night_q[:, None], qmax(kinds, p, rating, pv_night_q=True), day)


def _real_array(label: str, value: object) -> np.ndarray:
    """A float copy of `value`; complex or non-numeric input is an error (never truncated)."""
    try:
        arr = np.array(value)
    except ValueError:  # ragged nested lists
        raise InputError(f"scenario: {label} is not a regular array (rows of different lengths)") from None
    if np.iscomplexobj(arr):
        raise InputError(f"scenario: {label} must be real, got complex values")
    try:
        return np.array(arr, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"scenario: {label} must be numeric, got {arr.dtype} values") from None


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
