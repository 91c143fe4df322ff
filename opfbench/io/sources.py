"""The case sources a spec may name, declared once: how a spec's SOURCE is recognized, how
every help and error text describes it (`formats`), and how it is read into a `Case`.

A new source is its reader's module and one entry in `SOURCES`; the readers' heavy imports
stay inside them, so naming the formats costs nothing. The shipped names (no prefix or
suffix) take every SOURCE no other source claims.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from opfbench.errors import CaseFormatError, InputError

if TYPE_CHECKING:
    from opfbench.io.case import Case
    from opfbench.io.spec import CaseSpec

Reader = Callable[["CaseSpec", float], "Case"]  # (spec, the inverters' der-pf) → the case as its source gives it


@dataclass(frozen=True)
class CaseSource:
    """A source of cases: `kind` (what `CaseSpec.kind` says), `shown` (how help texts name
    it), `prefix` or `suffix` of the SOURCE it claims (neither: every other name), `file`
    (SOURCE is a file's path: cached by its modification time and size; `folder`: and by
    the newest file in its folder, which it reads too), `read`."""

    kind: str
    shown: str
    read: Reader
    prefix: str = ""
    suffix: str = ""
    file: bool = False
    folder: bool = False

    def path(self, source: str) -> Path:
        """The file a file source's SOURCE names (its prefix dropped)."""
        return Path(source.removeprefix(self.prefix))

    def claims(self, source: str) -> bool:
        """`source` is this source's (a source without prefix or suffix claims none: it
        takes what the others leave)."""
        return bool(self.prefix and source.startswith(self.prefix)) or bool(self.suffix and source.endswith(self.suffix))


def _simbench(spec: CaseSpec, der_pf: float) -> Case:
    from opfbench.io.disk_cache import cached_case
    from opfbench.io.simbench import simbench_case

    code = spec.source.removeprefix("simbench:")
    return cached_case(spec.text, lambda: simbench_case(spec.text, code, der_pf))


def _matpower(spec: CaseSpec, der_pf: float) -> Case:
    from opfbench.io.case import Case
    from opfbench.io.matpower import read_case_file

    net, der_p = read_case_file(spec.source, None, der_pf if spec.der == "gens" else None)
    stored = None
    if spec.der == "gens":
        loads = net.load_p_mw[net.load_bus], net.load_q_mvar[net.load_bus]
        stored = (*loads, der_p, np.zeros_like(der_p))
    return Case(spec.text, net, stored)


def _pandapower(spec: CaseSpec, der_pf: float) -> Case:
    import pandapower

    from opfbench.io.case import Case
    from opfbench.io.pandapower import from_pandapower

    path = Path(spec.source)
    try:
        pnet = pandapower.from_json(str(path))
    except Exception as exc:  # noqa: BLE001 — pandapower raises anything from json, pandas or its own checks
        raise CaseFormatError(
            f"{path}: not a pandapower net saved with pandapower.to_json ({type(exc).__name__}: {exc})"
        ) from None
    if not isinstance(pnet, pandapower.pandapowerNet) or "bus" not in pnet or "ext_grid" not in pnet:
        raise CaseFormatError(f"{path}: not a pandapower net (no bus and ext_grid tables)")
    conv = from_pandapower(pnet, path.stem, der_pf=der_pf, label=str(path))
    stored = (conv.stored_load_p_mw, conv.stored_load_q_mvar, conv.stored_der_p_mw, conv.stored_der_q_mvar)
    return Case(spec.text, conv.network, stored, None, conv.short_circuit, conv.notes, conv.load_index, conv.sgen_index)


OPENDSS = "opendss:"


def _opendss(spec: CaseSpec, der_pf: float) -> Case:
    from opfbench.io.opendss import opendss_case

    return opendss_case(spec, Path(spec.source.removeprefix(OPENDSS)), None)


def _shipped(spec: CaseSpec, der_pf: float) -> Case:
    from opfbench.cases import CASE_NAMES, shipped_network
    from opfbench.cases.opendss_cases import OPENDSS_NAMES
    from opfbench.io.case import Case
    from opfbench.io.opendss import opendss_case

    if spec.source in OPENDSS_NAMES:
        return opendss_case(spec, None, spec.source)
    if spec.source not in CASE_NAMES:
        names = ", ".join(CASE_NAMES + OPENDSS_NAMES)
        raise InputError(f"unknown case {spec.source!r}: give one of {names}, or {formats(without='shipped')}")
    return Case(spec.text, shipped_network(spec.source))


SOURCES: tuple[CaseSource, ...] = (
    CaseSource("shipped", "a shipped case's name (`opfbench cases`)", _shipped),
    CaseSource("matpower", "a MATPOWER .m file", _matpower, suffix=".m", file=True),
    CaseSource("pandapower", "a pandapower .json file (pandapower.to_json)", _pandapower, suffix=".json", file=True),
    CaseSource(
        "simbench",
        "simbench:CODE (a SimBench LV/MV grid with its own profiles, e.g. simbench:1-MV-rural--0-sw)",
        _simbench,
        prefix="simbench:",
    ),
    CaseSource(
        "opendss",
        "opendss:PATH (an OpenDSS master file, read by OpenDSS itself: a three-phase feeder)",
        _opendss,
        prefix=OPENDSS,
        file=True,
        folder=True,
    ),
)
"""Every source, in the order help texts name them."""


def source_of(source: str) -> CaseSource:
    """The source that claims the SOURCE text `source`; the shipped names take the rest."""
    claimed = [s for s in SOURCES if s.claims(source)]
    return claimed[0] if claimed else next(s for s in SOURCES if not (s.prefix or s.suffix))


def formats(without: str = "") -> str:
    """The sources as every help and error text names them (without the kind `without`)."""
    shown = [s.shown for s in SOURCES if s.kind != without]
    return ", ".join(shown[:-1]) + " or " + shown[-1] if len(shown) > 1 else shown[0]
