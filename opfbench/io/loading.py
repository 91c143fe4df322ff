"""Case sources behind one interface: `load_case(spec)` → `Case` (network, stored
operating point, its own time series when it has them, notes; the network a balanced
`Network` or, for OpenDSS feeders, a three-phase `PhaseNetwork`).

Specs (`opfbench.io.spec`): a SOURCE of one of the sources `opfbench.io.sources` declares
(the shipped names, MATPOWER `.m` and pandapower `.json` files, SimBench grids; its
`formats()` names them in every help and error text), with the options `der=`, `der-pf=`
and `line-z=` (a perturbed model). Cases are cached per process by spec (files also by
their modification time and size, an OpenDSS master also by the newest file in its
folder), so a worker that runs many tasks of one case reads it once; SimBench grids and
OpenDSS feeders, slow to read, also on disk across processes (`opfbench.io.disk_cache`).
"""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from opfbench.errors import InputError
from opfbench.io.case import Case, CaseSeries
from opfbench.io.sources import formats, source_of
from opfbench.io.spec import DEFAULT_DER_PF, CaseSpec, parse_der_list, parse_spec
from opfbench.multiphase import PhaseNetwork
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
    source = source_of(spec.source)
    return file_stamp(source.path(spec.source), source.folder) if source.file else ()


def file_stamp(path: Path, folder: bool = False) -> tuple:
    """(path, modification time, size) of a case file; with `folder` also the newest
    modification time in its folder (the files an OpenDSS master reads)."""
    try:
        st = path.stat()
    except OSError:
        raise InputError(f"case file {str(path)!r} not found (a case is {formats()})") from None
    stamp: tuple = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    if folder:
        stamp += (max((f.stat().st_mtime_ns for f in path.resolve().parent.rglob("*") if f.is_file()), default=0),)
    return stamp


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
    """The balanced network of `load_case(spec)`; InputError for a three-phase feeder
    (`load_case` gives its `PhaseNetwork`)."""
    return load_case(spec).balanced("this command (for now only `opfbench pf` and `opfbench cases` read three-phase feeders)")


def _read(spec: CaseSpec) -> Case:
    der_pf = DEFAULT_DER_PF if spec.der_pf is None else spec.der_pf
    case = source_of(spec.source).read(spec, der_pf)
    if isinstance(case.network, PhaseNetwork):
        from opfbench.io.opendss import with_ders

        if spec.line_z is not None:
            raise InputError(f"case {spec.text!r}: line-z= applies to balanced cases; this is a three-phase feeder")
        if spec.der == "gens":
            raise InputError(f"case {spec.text!r}: der=gens reads a MATPOWER file's generators; this is a three-phase feeder")
        return with_ders(case, spec, der_pf)
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
    net = case.balanced("der=")
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
    net = case.balanced("line-z=")
    line = (net.base_kv[net.f] == net.base_kv[net.t]) & (net.tap == 1.0) & (net.shift == 0.0)
    scale = np.where(line, factor, 1.0)
    note = f"line-z={factor!r}: the series impedance of {int(line.sum())} lines × {factor:g} (a perturbed model)"
    return dataclasses.replace(case, network=net.with_changes(r=net.r * scale, x=net.x * scale), notes=case.notes + (note,))
