"""Case sources behind one interface: `load_case(spec)` → `Case` (network, stored
operating point, its own time series when it has them, notes).

Specs (`opfbench.io.spec`): a shipped name (`opfbench.cases`), a MATPOWER `.m` file
(`opfbench.io.matpower`, reader and writer), a pandapower net saved as `.json`
(`opfbench.io.pandapower`) or `simbench:CODE` (`opfbench.io.simbench`), each with the
options `der=`, `der-pf=` and `line-z=` (a perturbed model). Cases are cached per process by spec (files also by their
modification time and size), so a worker that runs many tasks of one case reads it once;
SimBench grids, slow to extract, also on disk across processes (`opfbench.io.cache`).
"""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from opfbench.errors import CaseFormatError, InputError
from opfbench.io.case import Case, CaseSeries
from opfbench.io.spec import CaseSpec, parse_der_list, parse_spec
from opfbench.network import DER, Network
from opfbench.state import PROCESS

__all__ = ["NO_DER_NOTE", "Case", "CaseSeries", "CaseSpec", "load_case", "load_network", "parse_spec"]

CACHE_SIZE = 32  # cases kept per process (a SimBench MV grid with its profiles: ~20 MB)
NO_DER_NOTE = (
    "the case has no DER: every strategy gives the no-action result; add DER with --der BUS:KIND:MW,… "
    "(or --der gens for a MATPOWER file's generators)"
)
_cache: OrderedDict[tuple, Case] = OrderedDict()
_lock = threading.Lock()


def _forget_cases() -> None:
    with _lock:
        _cache.clear()


PROCESS.on_reset("cases read", _forget_cases)


def _stamp(spec: CaseSpec) -> tuple:
    if spec.kind in ("matpower", "pandapower"):
        path = Path(spec.source)
        try:
            st = path.stat()
        except OSError:
            raise InputError(
                f"case file {spec.source!r} not found (a shipped case name, a .m or .json path, or simbench:CODE)"
            ) from None
        return (str(path.resolve()), st.st_mtime_ns, st.st_size)
    return ()


def load_case(spec: str) -> Case:
    """The case named by `spec` (see the module docstring); InputError / CaseFormatError /
    DataError with one message naming the input otherwise."""
    parsed = parse_spec(spec)
    key = (parsed.text, _stamp(parsed))
    with _lock:
        case = _cache.get(key)
        if case is not None:
            _cache.move_to_end(key)
            return case
    case = _read(parsed)
    with _lock:
        _cache[key] = case
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)
    return case


def load_network(spec: str) -> Network:
    """The network of `load_case(spec)`."""
    return load_case(spec).network


def _read(spec: CaseSpec) -> Case:
    from opfbench.io.pandapower import DEFAULT_DER_PF

    der_pf = DEFAULT_DER_PF if spec.der_pf is None else spec.der_pf
    if spec.kind == "simbench":
        from opfbench.io.cache import cached_case
        from opfbench.io.simbench import simbench_case

        code = spec.source.removeprefix("simbench:")
        case = cached_case(spec.text, lambda: simbench_case(spec.text, code, der_pf))
    elif spec.kind == "matpower":
        from opfbench.io.matpower import read_case_file

        net, der_p = read_case_file(spec.source, None, der_pf if spec.der == "gens" else None)
        stored = None
        if spec.der == "gens":
            loads = net.load_p_mw[net.load_bus], net.load_q_mvar[net.load_bus]
            stored = (*loads, der_p, np.zeros_like(der_p))
        case = Case(spec.text, net, stored)
    elif spec.kind == "pandapower":
        case = _pandapower_case(spec, der_pf)
    else:
        from opfbench.cases import CASE_NAMES, shipped_network

        if spec.source not in CASE_NAMES:
            raise InputError(
                f"unknown case {spec.source!r}: give one of {', '.join(CASE_NAMES)}, the path of a MATPOWER .m or "
                "pandapower .json file, or simbench:CODE (e.g. simbench:1-MV-rural--0-sw)"
            )
        case = Case(spec.text, shipped_network(spec.source))
    if spec.der is not None and spec.der != "gens":
        case = _with_listed_ders(case, spec, der_pf)
    if spec.line_z is not None:
        case = _with_line_impedances(case, spec.line_z)
    if not case.network.ders:
        case = Case(
            case.spec,
            case.network,
            case.stored,
            case.series,
            case.short_circuit,
            case.notes + (NO_DER_NOTE,),
            case.load_index,
            case.der_index,
        )
    return case


def _with_listed_ders(case: Case, spec: CaseSpec, der_pf: float) -> Case:
    """`case` with the DER of the spec's `der=` list (only on a case without DER)."""
    net = case.network
    if net.ders:
        raise InputError(f"case {spec.text!r}: the case already has {len(net.ders)} DER; der= places DER on a case without")
    ders = []
    for e in parse_der_list(spec.der or "", spec.text):
        if e.bus not in set(int(b) for b in net.bus_ids):
            raise InputError(
                f"case {spec.text!r}: DER at bus {e.bus}: no such bus (buses {net.bus_ids.min()}..{net.bus_ids.max()})"
            )
        s = e.rating_mw / der_pf if e.kind == "inverter" else None
        ders.append(DER(net.index_of(e.bus), e.kind, e.rating_mw, s, e.energy))  # type: ignore[arg-type]
    return Case(spec.text, net.with_changes(ders=tuple(ders)), None, case.series, case.short_circuit, case.notes, case.load_index)


def _with_line_impedances(case: Case, factor: float) -> Case:
    """`case` with every line's r and x times `factor` (`opfbench.io.spec`: line-z)."""
    net = case.network
    line = (net.base_kv[net.f] == net.base_kv[net.t]) & (net.tap == 1.0) & (net.shift == 0.0)
    scale = np.where(line, factor, 1.0)
    note = f"line-z={factor!r}: the series impedance of {int(line.sum())} lines × {factor:g} (a perturbed model)"
    return dataclasses.replace(case, network=net.with_changes(r=net.r * scale, x=net.x * scale), notes=case.notes + (note,))


def _pandapower_case(spec: CaseSpec, der_pf: float) -> Case:
    import pandapower

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
    return Case(
        spec.text,
        conv.network,
        stored,
        None,
        conv.short_circuit,
        conv.notes,
        conv.load_index,
        conv.sgen_index,
    )
