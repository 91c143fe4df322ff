"""pandapower `runpp` on SimBench's own net as the test-time oracle of the converter: the
element values of a profile step come from SimBench's own `get_absolute_values` (not from
opfbench's series), and the row from the profile table's own time strings."""

from __future__ import annotations

import copy
import warnings
from functools import lru_cache

import numpy as np
import pandapower as pp
import simbench

from opfbench.io.simbench import simbench_net

#: The profile steps of the acceptance table: noon in June, a night, November (local
#: time strings exactly as in SimBench's time column).
STEPS = {"june-noon": "21.06.2016 12:00", "night": "15.01.2016 03:00", "november": "08.11.2016 12:00"}


@lru_cache(maxsize=None)
def _net(code: str):
    """SimBench's net of `code` with the taps made active (opfbench's own fix), read once."""
    return simbench_net(code)[0]


def fresh_net(code: str, fix_taps: bool = True):
    """A copy of the net to change; `fix_taps=False` restores simbench's empty
    tap_changer_type (pandapower then ignores the taps)."""
    net = copy.deepcopy(_net(code))
    if not fix_taps:
        net.trafo["tap_changer_type"] = None
    return net


@lru_cache(maxsize=None)
def absolute_values(code: str) -> dict:
    net = _net(code)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simbench.get_absolute_values(net, profiles_instead_of_study_cases=True)


def row_of(code: str, local: str) -> int:
    """The profile row whose SimBench time string is `local` (a unique one)."""
    net = _net(code)
    rows = np.flatnonzero(net.profiles["load"]["time"].to_numpy() == local)
    assert rows.size == 1, f"{local} is not a unique SimBench time"
    return int(rows[0])


def runpp_at(code: str, step: str | None, fix_taps: bool = True):
    """(pandapower net after runpp, losses kW) at the stored values (`step` None) or the
    profile step `step` (a key of STEPS); `fix_taps=False` keeps simbench's empty
    tap_changer_type (pandapower then ignores the taps)."""
    net = fresh_net(code, fix_taps)
    if step is not None:
        row = row_of(code, STEPS[step])
        values = absolute_values(code)
        for (element, column), frame in values.items():
            if element in ("load", "sgen") and column in ("p_mw", "q_mvar") and frame.shape[1]:
                net[element].loc[frame.columns, column] = frame.iloc[row].to_numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.runpp(net, tolerance_mva=1e-11, numba=False)
    losses = (net.res_line.pl_mw.sum() + net.res_trafo.pl_mw.sum()) * 1e3
    return net, float(losses)
