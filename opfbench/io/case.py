"""A case: its network, plus what the source knows beyond the network — the stored
operating point of every element, its own time series (per-load P and Q, per-DER P),
the upstream grid's short-circuit data and notes on how it was read."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd

from opfbench.errors import InputError
from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network


@dataclass(frozen=True, eq=False)
class CaseSeries:
    """Per-element time series as per-unit profiles and each element's base: element e's
    value at row i is `pu[i, col[e]] × base[e]` (MW or MVAr). `index` is tz-aware and
    strictly increasing; `source` says where the profiles come from."""

    index: pd.DatetimeIndex
    load_p_pu: np.ndarray
    load_p_col: np.ndarray
    load_p_base_mw: np.ndarray
    load_q_pu: np.ndarray
    load_q_col: np.ndarray
    load_q_base_mvar: np.ndarray
    der_pu: np.ndarray
    der_col: np.ndarray
    der_base_mw: np.ndarray
    source: str

    def __post_init__(self) -> None:
        for name in ("load_p_pu", "load_q_pu", "der_pu"):
            getattr(self, name).setflags(write=False)

    @property
    def step(self) -> pd.Timedelta:
        return self.index[1] - self.index[0]

    def rows(self, times: pd.DatetimeIndex) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(load P (S, n_load) MW, load Q (S, n_load) MVAr, DER P (S, n_der) MW) at the
        instants `times`: the profile rows where they match, linear interpolation in
        time between rows otherwise; InputError for instants outside the series."""
        times = pd.DatetimeIndex(times)
        if times.tz is None:
            raise InputError("case series: times must be time-zone aware")
        if len(times) and (times[0] < self.index[0] or times[-1] > self.index[-1]):
            raise InputError(
                f"case series: {times[0]} .. {times[-1]} leaves the case's profiles ({self.index[0]} .. {self.index[-1]})"
            )
        pos = self.index.get_indexer(times)
        if (pos >= 0).all():
            take = lambda pu, col, base: pu[pos][:, col] * base  # noqa: E731
        else:
            x = times.as_unit("ns").asi8
            xp = self.index.as_unit("ns").asi8
            hi = np.clip(np.searchsorted(xp, x, side="left"), 1, len(xp) - 1)
            w = ((x - xp[hi - 1]) / (xp[hi] - xp[hi - 1]))[:, None]

            def take(pu: np.ndarray, col: np.ndarray, base: np.ndarray) -> np.ndarray:
                return ((1 - w) * pu[hi - 1][:, col] + w * pu[hi][:, col]) * base

        return (
            take(self.load_p_pu, self.load_p_col, self.load_p_base_mw),
            take(self.load_q_pu, self.load_q_col, self.load_q_base_mvar),
            take(self.der_pu, self.der_col, self.der_base_mw),
        )


@dataclass(frozen=True, eq=False)
class Case:
    """What `opfbench.io.load_case` returns: `network` a balanced `Network` or, for OpenDSS
    feeders, a three-phase `PhaseNetwork`. `stored`: (load P, load Q, DER P, DER Q) per
    element as the source stores them (None: the source has no per-element operating
    point, e.g. a MATPOWER file's DER); `series`: the case's own time series or None;
    `short_circuit`: (S″k MVA, R/X) of the upstream grid at the slack, None when the
    source gives none; `notes`: what the conversion did that a user should know;
    `load_index` / `der_index`: the source's row of each load element and DER (the
    pandapower `load` and `sgen` index; None for sources without such rows)."""

    spec: str
    network: Network | PhaseNetwork
    stored: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    series: CaseSeries | None = None
    short_circuit: tuple[float, float] | None = None
    notes: tuple[str, ...] = ()
    load_index: np.ndarray | None = None
    der_index: np.ndarray | None = None

    def __post_init__(self) -> None:
        """The stored operating point and the source rows are read-only: a case is cached
        and shared (`opfbench.io.load_case`), so a caller's write would reach every other."""
        for arr in (*(self.stored or ()), self.load_index, self.der_index):
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)

    @property
    def name(self) -> str:
        return self.network.name

    def balanced(self, what: str) -> Network:
        """The balanced network; InputError naming the case and `what` (the work that needs
        a balanced model) for a three-phase feeder."""
        if isinstance(self.network, PhaseNetwork):
            raise InputError(f"{what} needs a balanced case; {self.spec} is a three-phase (unbalanced) feeder")
        return self.network

    @cached_property
    def data_sha256(self) -> str:
        """Hash of the case's data (`opfbench.digests`): network, stored operating point,
        time series, short-circuit data — everything but the spec that names it."""
        from opfbench.digests import digest

        series = self.series
        profiles = None
        if series is not None:
            index = (series.index.asi8, str(series.index.tz))
            profiles = {name: getattr(series, name) for name in series.__dataclass_fields__ if name != "index"} | {"index": index}
        return digest(
            [self.network, self.stored, profiles, self.short_circuit, list(self.notes), self.load_index, self.der_index]
        )
