"""Embedded public time series and the profiles built from them.

Loaders read compact derived files shipped in ``opfbench/data/files`` (provenance and
licences in ``files/PROVENANCE.md``); ``python -m opfbench.data.derive --source DIR``
regenerates them from the raw sources.
"""

from opfbench.data.loaders import load_pv_minute, load_simbench_profiles, load_wind_hourly
from opfbench.data.night import night_mask, night_mask_window
from opfbench.data.profiles import PAPER_DAY, assemble_profiles, paper_day

__all__ = [
    "PAPER_DAY",
    "assemble_profiles",
    "load_pv_minute",
    "load_simbench_profiles",
    "load_wind_hourly",
    "night_mask",
    "night_mask_window",
    "paper_day",
]
