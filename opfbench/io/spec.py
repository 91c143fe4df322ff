"""Case specs: the one string that names a case everywhere (command line, config, task,
worker, tables).

    SOURCE[?der=DER&der-pf=PF&line-z=F&taps=MODE]

SOURCE is one of the case sources `opfbench.io.sources` declares (its `formats()` names
them: the shipped names, MATPOWER `.m` and pandapower `.json` files, `simbench:CODE`,
`opendss:PATH`). Options:

- `der=gens` (MATPOWER files): the case's non-slack generators become DER
  (`opfbench.io.matpower`); `der=BUS:KIND:MW[:ENERGY],…`: DER placed at those buses
  (external bus numbers; KIND PV or DFIG — the paper's units, S̄ = P̄ — or inverter, a
  generic inverter with S̄ = P̄/der-pf; ENERGY solar, wind, biomass, hydro or other,
  default: PV solar, DFIG wind, inverter solar). Only on a case without DER.
- `der-pf=PF` in (0, 1]: the generic inverters' rating S̄ = P̄/PF where the source gives
  no larger nameplate (pandapower/SimBench static generators, generators as DER, `der=`
  inverters). Default 0.90, VDE-AR-N 4105's power factor at full output.
- `line-z=F`, F > 0: a perturbed model — every line's series impedance r + jx is F times
  the source's (transformers, shunts and line charging unchanged; a line is a branch
  between buses of one base voltage, without tap or phase shift). Every strategy runs on
  the perturbed grid, and a learned rule trained in the same run is fitted on the case's
  model (`CaseSpec.model`: the spec without `line-z`), the operator's view of the grid:
  its result on the perturbed case is the price of model error.

- `taps=held|control` (three-phase feeders): the regulators' taps held where OpenDSS
  settled the file's own snapshot (`held`, the default), or moved in every power flow by
  opfbench's emulation of OpenDSS's static RegControl (`control`:
  `opfbench.multiphase.regulators`; each snapshot starts from the taps the file compiles
  to, as OpenDSS's snapshot solve does).

An option at its default (der-pf=0.9, line-z=1) is the case without it: one text per case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from opfbench.errors import InputError
from opfbench.exact import number_text
from opfbench.io.sources import formats, source_of
from opfbench.network import DER_ENERGIES, DER_KINDS

DEFAULT_DER_PF = 0.90  # S̄ = P̄ / 0.90: VDE-AR-N 4105's cos φ 0.90 at full output
NOMINAL_LINE_Z = 1.0  # line-z's identity: the source's impedances
TAP_MODES = ("held", "control")  # taps=: the first is the default


@dataclass(frozen=True)
class CaseSpec:
    """A parsed case spec (see the module docstring)."""

    source: str
    der: str | None = None
    der_pf: float | None = None
    line_z: float | None = None
    taps: str | None = None

    @property
    def text(self) -> str:
        """The canonical spec string."""
        opts = [f"der={self.der}"] if self.der is not None else []
        opts += [f"der-pf={number_text(self.der_pf)}"] if self.der_pf is not None else []
        opts += [f"line-z={number_text(self.line_z)}"] if self.line_z is not None else []
        opts += [f"taps={self.taps}"] if self.taps is not None else []
        return self.source + ("?" + "&".join(opts) if opts else "")

    @property
    def model(self) -> "CaseSpec":
        """The case as modelled: this spec without its perturbation (`line-z`)."""
        return CaseSpec(self.source, self.der, self.der_pf, taps=self.taps)

    @property
    def three_phase(self) -> bool:
        """The spec names a three-phase feeder (an `opendss:` file or a shipped OpenDSS feeder)."""
        from opfbench.cases.opendss_cases import OPENDSS_NAMES

        return self.kind == "opendss" or self.source in OPENDSS_NAMES

    @property
    def kind(self) -> str:
        """The kind of its source (`sources.SOURCES`: "shipped", "matpower", …)."""
        return source_of(self.source).kind


def parse_spec(text: str) -> CaseSpec:
    """The CaseSpec of `text`; InputError naming the option for a malformed one."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"a case is {formats()}, got {text!r}")
    source, sep, query = text.strip().partition("?")
    der, der_pf, line_z, taps = None, None, None, None
    seen: set[str] = set()
    for part in query.split("&") if sep else ():
        key, eq, value = part.partition("=")
        if not eq or not value:
            raise InputError(f"case {text!r}: option {part!r} must be key=value (der=…, der-pf=…, line-z=…, taps=…)")
        if key in seen:
            raise InputError(
                f"case {text!r}: option {key} given twice (as --{key} and ?{key}=, or twice in the spec); give it once"
            )
        seen.add(key)
        if key == "der":
            der = value
        elif key == "der-pf":
            try:
                der_pf = float(value)
            except ValueError:
                raise InputError(f"case {text!r}: der-pf must be a number in (0, 1], got {value!r}") from None
            if not math.isfinite(der_pf):
                raise InputError(f"case {text!r}: der-pf must be a number in (0, 1], got {value!r}")
            if not 0 < der_pf <= 1:
                raise InputError(f"case {text!r}: der-pf must lie in (0, 1], got {value}")
        elif key == "line-z":
            line_z = _factor(text, value)
        elif key == "taps":
            if value not in TAP_MODES:
                raise InputError(f"case {text!r}: taps must be one of {', '.join(TAP_MODES)}, got {value!r}")
            taps = value
        else:
            raise InputError(f"case {text!r}: unknown option {key!r} (der, der-pf, line-z, taps)")
    # one text per case: an option at its default is the case without it (as in strategy labels)
    spec = CaseSpec(
        source,
        der,
        None if der_pf == DEFAULT_DER_PF else der_pf,
        None if line_z == NOMINAL_LINE_Z else line_z,
        None if taps == TAP_MODES[0] else taps,
    )
    if spec.taps is not None and not spec.three_phase:
        raise InputError(f"case {text!r}: taps= applies to three-phase (OpenDSS) feeders; this case is {spec.kind}")
    if der is not None and der != "gens":
        parse_der_list(der, text, phased=spec.three_phase)
    if spec.kind == "opendss" and not spec.source.removeprefix("opendss:").strip():
        raise InputError(f"case {text!r}: opendss: needs the path of an OpenDSS master file, e.g. opendss:my/Master.dss")
    if der == "gens" and spec.kind != "matpower":
        raise InputError(f"case {text!r}: der=gens reads a MATPOWER file's generators; this case is {spec.kind}")
    return spec


def _factor(text: str, value: str) -> float:
    """line-z's factor: a finite number > 0 (e.g. 1.2: impedances +20 %)."""
    try:
        factor = float(value)
    except ValueError:
        raise InputError(f"case {text!r}: line-z must be a number > 0 (e.g. 1.2: line impedances +20 %), got {value!r}") from None
    if not (0 < factor < float("inf")):
        raise InputError(f"case {text!r}: line-z must be a finite number > 0, got {value}")
    return factor


@dataclass(frozen=True)
class DerEntry:
    """One `der=` item: external bus number (a three-phase feeder's: the OpenDSS bus name,
    lower case), kind, rated P̄ (MW), primary energy, and on a three-phase feeder the
    phases it connects to (`BUS.1.2`; () = every phase of the bus)."""

    bus: int | str
    kind: str
    rating_mw: float
    energy: str
    phases: tuple[int, ...] = ()


def parse_der_list(value: str, spec: str, phased: bool = False) -> tuple[DerEntry, ...]:
    """`BUS:KIND:MW[:ENERGY],…` → entries; on a three-phase feeder (`phased`) BUS is an
    OpenDSS bus name with optional phases, `BUS[.PHASE…]` (e.g. `675.1`, `611.3`,
    `sourcebus`); InputError naming the item otherwise."""
    kinds = {k.lower(): k for k in DER_KINDS}
    out = []
    for item in value.split(","):
        parts = item.strip().split(":")
        if len(parts) not in (3, 4):
            raise InputError(f"case {spec!r}: DER {item!r} must be BUS:KIND:MW[:ENERGY], e.g. 10:PV:0.5")
        bus_text, kind_text, mw_text = parts[:3]
        bus: int | str
        phases: tuple[int, ...] = ()
        try:
            mw = float(mw_text)
            if phased:
                bus, *phase_texts = bus_text.strip().lower().split(".")
                phases = tuple(int(p) for p in phase_texts)
                if not bus or any(p not in (1, 2, 3) for p in phases) or len(set(phases)) != len(phases):
                    raise ValueError
            else:
                bus = int(bus_text)
        except ValueError:
            what = "an OpenDSS bus name BUS[.PHASE…] (phases 1, 2, 3, each once)" if phased else "a bus number"
            raise InputError(f"case {spec!r}: DER {item!r}: BUS must be {what} and MW a number") from None
        kind = kinds.get(kind_text.lower())
        if kind is None:
            raise InputError(f"case {spec!r}: DER {item!r}: KIND must be one of {', '.join(DER_KINDS)}")
        if not (mw > 0 and mw < float("inf")):
            raise InputError(f"case {spec!r}: DER {item!r}: MW must be a positive number")
        default = {"PV": "solar", "DFIG": "wind"}.get(kind, "solar")
        energy = parts[3].lower() if len(parts) == 4 else default
        if energy not in DER_ENERGIES:
            raise InputError(f"case {spec!r}: DER {item!r}: ENERGY must be one of {', '.join(DER_ENERGIES)}")
        out.append(DerEntry(bus, kind, mw, energy, phases))
    return tuple(out)
