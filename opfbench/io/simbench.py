"""`simbench:CODE` — a SimBench LV or MV grid (PyPI `simbench`, offline) with its own
profiles of 2016 at 15 min, converted by `opfbench.io.pandapower`.

What SimBench's data need, each handled here (and tested):

- **Taps**: simbench 1.6.3 leaves `tap_changer_type` empty, so pandapower 3.x silently
  ignores `tap_pos` (1-MV-urban's two transformers sit at tap −1). Every transformer with
  a tap position and step but no changer type is given the "Ratio" type, so the taps act
  as SimBench intends; the case's notes say which.
- **Slack** at the external grid's 1.025 p.u. (not 1.0) and SimBench's voltage limits
  (0.965–1.055 p.u. on MV buses): kept as given.
- **Stored values**: the stored sgen output equals its rating (and the loads their
  reference values): the stored operating point is kept as such (`Case.stored`), the
  time series are the profiles × these values (SimBench's own rule,
  `simbench.get_absolute_profiles_from_relative_profiles`).
- **Local time**: the profiles' time column is German local time with daylight saving (a
  missing hour on 27 March, a repeated one on 30 October): read by
  `opfbench.data.simbench_profiles.simbench_time_index` into a strictly increasing tz-aware index.
- **Signs**: negative profile values are real (wind turbines' own consumption −1e-5 p.u.,
  capacitive load Q) and are never clipped.
- **Structure**: several loads (and sgens) share a bus, bus indices are not contiguous,
  closed bus-bus switches fuse the two parallel HV/MV transformers' buses (merged into one
  branch), open loop switches open their lines' ends.

Only LV, MV and MV+LV codes are taken: HV and EHV grids are meshed transmission grids with
voltage-controlled generators (pandapower `gen`), which the local rules and the
formulations do not model.
"""

from __future__ import annotations

import difflib
import warnings
from functools import lru_cache

import numpy as np
import pandas as pd

from opfbench.errors import DataError, InputError
from opfbench.io.case import Case, CaseSeries
from opfbench.io.pandapower import from_pandapower
from opfbench.io.spec import DEFAULT_DER_PF

PREFIX = "simbench:"
SIMBENCH_TZ = "Europe/Berlin"
SIMBENCH_STEP = pd.Timedelta("15min")
ACCEPTED_LEVELS = ("LV", "MV", "MVLV")
#: The field suite: every SimBench LV and MV grid of scenario 0, switch variant "sw".
SUITE = (
    "1-MV-rural--0-sw",
    "1-MV-semiurb--0-sw",
    "1-MV-urban--0-sw",
    "1-MV-comm--0-sw",
    "1-LV-rural1--0-sw",
    "1-LV-rural2--0-sw",
    "1-LV-rural3--0-sw",
    "1-LV-semiurb4--0-sw",
    "1-LV-semiurb5--0-sw",
    "1-LV-urban6--0-sw",
)


def simbench_time_index(time: pd.Series, name: str) -> pd.DatetimeIndex:
    """SimBench's ``time`` column (``dd.mm.yyyy HH:MM``, German local clock with daylight
    saving) as a strictly increasing tz-aware (Europe/Berlin) 15-min index: the skipped
    hour is absent in the data, the repeated one is resolved by order; DataError naming
    `name` otherwise."""
    try:
        local = pd.DatetimeIndex(pd.to_datetime(time, format="%d.%m.%Y %H:%M"))
        index = local.tz_localize(SIMBENCH_TZ, ambiguous="infer", nonexistent="raise")
    except (ValueError, TypeError) as exc:  # pytz/zoneinfo errors subclass ValueError
        raise DataError(f"{name}: column 'time' cannot be read as Europe/Berlin local time ({exc})") from exc
    if len(index) < 2:
        raise DataError(f"{name}: column 'time' holds {len(index)} step(s)")
    steps = np.diff(index.as_unit("ns").asi8)
    bad = np.flatnonzero(steps != SIMBENCH_STEP.value)
    if bad.size:
        raise DataError(
            f"{name}: column 'time' is not strictly increasing by {SIMBENCH_STEP} at row {bad[0] + 1} ({index[bad[0] + 1]})"
        )
    return index


@lru_cache(maxsize=1)
def _all_codes() -> tuple[str, ...]:
    import simbench

    return tuple(simbench.collect_all_simbench_codes())


def accepted_codes() -> tuple[str, ...]:
    """Every SimBench code opfbench takes (LV, MV and MV+LV grids)."""
    return tuple(c for c in _all_codes() if c.split("-")[1] in ACCEPTED_LEVELS)


def check_code(code: str) -> str:
    """`code` if it is a SimBench LV/MV code, else InputError naming the closest codes, or
    saying why an HV/EHV grid is refused."""
    codes = _all_codes()
    if code not in codes:
        close = difflib.get_close_matches(code, accepted_codes(), n=3, cutoff=0.0)
        raise InputError(
            f"unknown SimBench code {code!r}; closest: {', '.join(close)} (all: simbench.collect_all_simbench_codes())"
        )
    level = code.split("-")[1]
    if level not in ACCEPTED_LEVELS:
        raise InputError(
            f"SimBench code {code!r} is a {level} grid: HV and EHV grids are meshed transmission grids with "
            "voltage-controlled generators (pandapower 'gen'), which opfbench's local rules and formulations do "
            f"not model; take an LV or MV grid, e.g. {', '.join(SUITE[:2])}"
        )
    return code


def simbench_net(code: str):
    """The pandapower net of SimBench `code` with its profiles, taps made active (see the
    module docstring); returns (net, notes)."""
    import simbench

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net = simbench.get_simbench_net(check_code(code))
    notes = []
    trafo = net.trafo
    empty = trafo["tap_changer_type"].isna() if "tap_changer_type" in trafo else pd.Series(True, index=trafo.index)
    has_tap = trafo["tap_pos"].notna() & trafo["tap_step_percent"].notna()
    fix = empty & has_tap
    if fix.any():
        trafo.loc[fix, "tap_changer_type"] = "Ratio"
        off = trafo.index[fix & (trafo["tap_pos"] != trafo["tap_neutral"])]
        notes.append(
            f"taps applied as SimBench intends: simbench {simbench.__version__} leaves tap_changer_type empty (pandapower 3.x "
            "would ignore tap_pos); set to 'Ratio'"
            + (f"; off-neutral: trafo {', '.join(f'{i} at tap {trafo.tap_pos[i]:g}' for i in off)}" if len(off) else "")
        )
    return net, notes


def _profiles(net, table: str, columns: pd.Index, code: str) -> tuple[pd.DatetimeIndex, pd.DataFrame]:
    frame = net.profiles[table]
    index = simbench_time_index(frame["time"], f"SimBench {code} profiles '{table}'")
    values = frame[list(columns)].apply(pd.to_numeric, errors="coerce")
    bad = values.isna().to_numpy()
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DataError(
            f"SimBench {code}: profile {values.columns[col]!r} ('{table}') has {int(bad[:, col].sum())} missing or non-numeric "
            f"value(s), first at {index[row]}"
        )
    return index, values.set_axis(index)


def _series(net, conv, code: str) -> CaseSeries:
    load = net.load.loc[conv.load_index]
    sgen = net.sgen.loc[conv.sgen_index]
    prof_load = load["profile"].astype(str)
    prof_sgen = sgen["profile"].astype(str)
    p_cols = pd.Index(sorted(set(prof_load + "_pload")))
    q_cols = pd.Index(sorted(set(prof_load + "_qload")))
    d_cols = pd.Index(sorted(set(prof_sgen)))
    for cols, table, elements in ((p_cols.union(q_cols), "load", "load"), (d_cols, "renewables", "sgen")):
        missing = sorted(set(cols) - set(net.profiles[table].columns))
        if missing:
            raise DataError(f"SimBench {code}: {elements} profile(s) {missing} not in net.profiles['{table}']")
    index, lp = _profiles(net, "load", p_cols, code)
    _, lq = _profiles(net, "load", q_cols, code)
    d_index, dp = _profiles(net, "renewables", d_cols, code)
    if not index.equals(d_index):
        raise DataError(f"SimBench {code}: the load and renewables profiles have different time columns")
    return CaseSeries(
        index,
        lp.to_numpy(dtype=float),
        p_cols.get_indexer(prof_load + "_pload"),
        conv.stored_load_p_mw,
        lq.to_numpy(dtype=float),
        q_cols.get_indexer(prof_load + "_qload"),
        conv.stored_load_q_mvar,
        dp.to_numpy(dtype=float),
        d_cols.get_indexer(prof_sgen),
        conv.stored_der_p_mw,
        f"SimBench {code} profiles 2016 at 15 min (per load P/Q, per sgen P)",
    )


def cigre_short_circuit(kv: float) -> tuple[float, float]:
    """(S″k MVA, R/X) of the upstream grid where a net gives none: the CIGRE benchmark
    networks' external grids (CIGRE TF C6.04.02, "Benchmark Systems for Network
    Integration of Renewable and Distributed Energy Resources", 2014; pandapower's
    `create_cigre_network_mv`/`_lv`): 5000 MVA, R/X 0.1 for a feeder from 110 kV (at
    ≥ 60 kV), 100 MVA, R/X 1.0 for a feeder from a medium-voltage bus."""
    return (5000.0, 0.1) if kv >= 60.0 else (100.0, 1.0)


def simbench_case(spec: str, code: str, der_pf: float = DEFAULT_DER_PF) -> Case:
    """The case `simbench:CODE`: network, stored operating point, profiles, notes."""
    net, notes = simbench_net(code)
    conv = from_pandapower(net, code, der_pf=der_pf, label=f"SimBench {code}")
    loads_without = net.load.loc[conv.load_index, "profile"].isna()
    sgens_without = net.sgen.loc[conv.sgen_index, "profile"].isna()
    if loads_without.any() or sgens_without.any():
        raise DataError(
            f"SimBench {code}: {int(loads_without.sum())} load(s) and {int(sgens_without.sum())} sgen(s) have no profile"
        )
    short_circuit = conv.short_circuit
    if short_circuit is None:
        kv = float(conv.network.base_kv[conv.network.slack])
        short_circuit = cigre_short_circuit(kv)
        notes.append(
            f"SimBench gives its external grid no short-circuit data: the fault study's upstream source is the CIGRE "
            f"benchmark value at {kv:g} kV, S″k {short_circuit[0]:g} MVA, R/X {short_circuit[1]:g}"
        )
    return Case(
        spec,
        conv.network,
        (conv.stored_load_p_mw, conv.stored_load_q_mvar, conv.stored_der_p_mw, conv.stored_der_q_mvar),
        _series(net, conv, code),
        short_circuit,
        tuple(notes) + conv.notes,
        conv.load_index,
        conv.sgen_index,
    )
