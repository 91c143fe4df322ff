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
    """S snapshots on one network. Arrays: load_scale (S,), der_p_mw (S, n_der),
    der_p_forecast_mw (S, n_der) or None; pv_night_q (S,) bool or None: snapshots where
    PV units have the S-limited "Q at night" capability (night mode "connected-q")."""

    net: Network
    load_scale: np.ndarray
    der_p_mw: np.ndarray
    der_p_forecast_mw: np.ndarray | None = None
    pv_night_q: np.ndarray | None = None

    def __post_init__(self) -> None:
        n_der = len(self.net.ders)
        ls = np.atleast_1d(np.asarray(self.load_scale, dtype=float))
        p = np.asarray(self.der_p_mw, dtype=float).reshape(ls.shape[0], n_der) if n_der == 0 else \
            np.atleast_2d(np.asarray(self.der_p_mw, dtype=float)).reshape(-1, n_der)
        if ls.shape[0] != p.shape[0]:
            raise InputError(f"scenario: {ls.shape[0]} load scales but {p.shape[0]} rows of DER power")
        _check_finite("load_scale", ls)
        _check_finite("der_p_mw", p)
        if np.any(ls < 0):
            raise InputError(f"scenario: load scale must be ≥ 0, got {ls.min()}")
        rating = self.net.der_rating_mw
        if np.any(p < 0) or np.any(p > rating * (1 + 1e-9)):
            raise InputError(f"scenario: DER active power must lie in [0, rating] MW; got range [{p.min():.4g}, {p.max():.4g}]")
        object.__setattr__(self, "load_scale", ls)
        object.__setattr__(self, "der_p_mw", p)
        if self.der_p_forecast_mw is not None:
            pf = np.asarray(self.der_p_forecast_mw, dtype=float).reshape(p.shape)
            _check_finite("der_p_forecast_mw", pf)
            if pf.shape != p.shape:
                raise InputError(f"scenario: forecast shape {pf.shape} differs from current DER power {p.shape}")
            object.__setattr__(self, "der_p_forecast_mw", np.clip(pf, 0.0, rating))

    @classmethod
    def snapshot(cls, net: Network, load_scale: float = 1.0, der_scale: float = 0.8,
                 forecast_der_scale: float | None = None) -> "Scenario":
        """One snapshot: every DER at `der_scale` × rating (and optionally a forecast)."""
        for label, value in (("der_scale", der_scale), ("forecast_der_scale", forecast_der_scale)):
            if value is not None and not 0 <= value <= 1:
                raise InputError(f"{label} is a fraction of rating and must lie in [0, 1], got {value}")
        rating = net.der_rating_mw
        forecast = None if forecast_der_scale is None else [forecast_der_scale * rating]
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

    @classmethod
    def from_profiles(cls, net: Network, load_pu: np.ndarray, pv_pu: np.ndarray, wind_pu: np.ndarray,
                      forecast_pv_pu: np.ndarray | None = None,
                      forecast_wind_pu: np.ndarray | None = None) -> "Scenario":
        """Snapshots from per-unit profiles (S,): loads follow `load_pu` × nominal load;
        PV units `pv_pu` × rating; DFIG units `wind_pu` × rating (the mapping rule of
        `opfbench.data.profiles`). Forecast profiles, when given, set P^F the same way."""
        is_pv = np.array([kind == "PV" for kind in net.der_kinds])

        def der_mw(pv: np.ndarray, wind: np.ndarray) -> np.ndarray:
            pv, wind = np.asarray(pv, dtype=float), np.asarray(wind, dtype=float)
            return np.where(is_pv, pv[:, None], wind[:, None]) * net.der_rating_mw

        forecast = None
        if forecast_pv_pu is not None or forecast_wind_pu is not None:
            forecast = der_mw(pv_pu if forecast_pv_pu is None else forecast_pv_pu,
                              wind_pu if forecast_wind_pu is None else forecast_wind_pu)
        return cls(net, np.asarray(load_pu, dtype=float), der_mw(pv_pu, wind_pu), forecast)

    def take(self, rows: np.ndarray | slice) -> "Scenario":
        """The sub-scenario of some snapshots."""
        fc = None if self.der_p_forecast_mw is None else self.der_p_forecast_mw[rows]
        night_q = None if self.pv_night_q is None else self.pv_night_q[rows]
        return Scenario(self.net, self.load_scale[rows], self.der_p_mw[rows], fc, night_q)

    # ----- "Q at night" (night mode connected-q) -------------------------------------------
    def with_night_q(self, mask: np.ndarray) -> "Scenario":
        """This scenario with PV units S-limited (|Q| ≤ √(S̄² − P²), no PF limit) at the
        snapshots where `mask` (S,) is True."""
        mask = np.asarray(mask, dtype=bool).reshape(-1)
        if mask.shape != (self.n_snapshots,):
            raise InputError(f"scenario: night-Q mask has {mask.size} values for {self.n_snapshots} snapshots")
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


def _check_finite(label: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"scenario: {label} has NaN or inf at index {tuple(int(i) for i in bad)}")
