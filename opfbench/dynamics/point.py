"""The fault study's operating point and its upstream source: the pre-fault snapshot a
study simulates, and the source impedance a case's short-circuit data give."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from opfbench.dynamics.params import ModelParams
from opfbench.errors import InputError
from opfbench.io import Case
from opfbench.network import Network
from opfbench.scenario import Scenario


@dataclass(frozen=True)
class OperatingPoint:
    """The pre-fault snapshot: `scenario` (forecast P^F = the oracle's, used only by
    forecast-aware strategies with forecast "oracle") and how it was chosen."""

    scenario: Scenario
    label: str

    @property
    def data_sha256(self) -> str:
        """Hash of the snapshot's data: loads, DER output and its forecast (`opfbench.digests`)."""
        from opfbench.digests import digest

        sc = self.scenario
        return digest([sc.load_scale, sc.der_p_mw, sc.der_p_forecast_mw, sc.load_p_mw, sc.load_q_mvar])


def operating_point(
    net: Network, load_scale: float = 1.0, der_scale: float = 0.8, time: str | None = None, case: Case | None = None
) -> OperatingPoint:
    """Nominal loads × load_scale with every DER at der_scale × rating (the oracle
    forecast of a snapshot is the snapshot itself), or the paper day's minute `time`
    ("HH:MM", local time) with the next minute as the oracle forecast — or, for a `case`
    with its own time series, the step of its profiles at `time` (local date and time,
    e.g. 2016-11-08T12:00) with the next step as the oracle forecast."""
    if time is not None and case is not None and case.series is not None:
        from opfbench.study.periods import local_time

        when = local_time(time, "--time")
        series = case.series
        row = series.index.get_indexer([when])[0]
        if row < 0:
            raise InputError(
                f"--time {time!r} is not a step of {case.spec}'s profiles ({series.index[0]} .. {series.index[-1]}, every {series.step})"
            )
        load_p, load_q, der_p = series.rows(series.index[[row, min(row + 1, len(series.index) - 1)]])
        sc = Scenario.from_series(net, load_p[:1], load_q[:1], der_p[:1], der_p[1:])
        return OperatingPoint(sc, f"{case.spec} profiles at {when.isoformat()}")
    if time is None:
        sc = Scenario.snapshot(net, load_scale, der_scale, forecast_der_scale=der_scale)
        return OperatingPoint(sc, f"load {load_scale:g} × nominal, DER at {der_scale:g} × rating")
    from opfbench.data import paper_day

    day = paper_day()
    hits = np.flatnonzero(day.index.strftime("%H:%M") == time)
    if hits.size == 0:
        raise InputError(f"--time must be HH:MM within the paper day (00:00..23:59), got {time!r}")
    i = int(hits[0])
    j = min(i + 1, len(day) - 1)
    sc = Scenario.from_profiles(
        net,
        day["load"].to_numpy()[i : i + 1],
        day["pv"].to_numpy()[i : i + 1],
        day["wind"].to_numpy()[i : i + 1],
        day["pv"].to_numpy()[j : j + 1],
        day["wind"].to_numpy()[j : j + 1],
    )
    return OperatingPoint(sc, f"paper day {day.index[i].isoformat()}")


def case_source(case: Case, params: ModelParams) -> ModelParams:
    """`params` with the upstream source of `case`'s short-circuit data, where it has some:
    |Z| = base_mva / S″k (p.u. on the case base, the Thevenin impedance of the upstream grid
    at rated voltage, IEC 60909 with c = 1), split by its R/X ratio."""
    if case.short_circuit is None:
        return params
    s_sc, rx = case.short_circuit
    z = case.balanced("the fault study (a balanced three-phase RMS model)").base_mva / s_sc
    x = z / np.hypot(1.0, rx)
    return replace(params, source=replace(params.source, impedance_pu=float(x), resistance_pu=float(rx * x)))
