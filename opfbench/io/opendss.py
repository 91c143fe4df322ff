"""Case source `opendss:PATH`: an OpenDSS model read by OpenDSS itself.

OpenDSS (`opendssdirect.py`, the ecosystem's own engine; no `.dss` parser here) compiles
the master file and solves its snapshot — `mode=snapshot`, its control loop on, so
regulator taps and switched capacitors settle; `tolerance=1e-10` (OpenDSS's default 1e-4
leaves the taps to the solver's error) and at least 100 iterations. opfbench's model
(`opfbench.multiphase.PhaseNetwork`) is then built from the compiled circuit, element by
element:

- lines and switches, transformers and regulators (at their settled taps), capacitors and
  reactors: their terminals' nodes (`CktElement.NodeOrder`) and primitive admittance
  (`CktElement.YPrim`); lines also their series impedance and shunt matrices (from that
  admittance) and length, transformers their windings;
- the Vsource: its EMF (`pu`·`basekV`, `angle`, positive sequence) behind its own
  primitive admittance;
- loads: branches with their nominal power (the admittance OpenDSS builds for them,
  × base voltage²: OpenDSS's own nominal, allocation factors and load multiplier
  included), their model (1, 2, 4, 5 with `vminpu`, `vmaxpu`, `vlowpu`, CVR factors) and
  their `status`: a `fixed` load stays at its nominal under any load multiplier and load
  shape, an `exempt` one under any load multiplier (`PhaseNetwork.load_fixed`; OpenDSS's
  `Load.SetNominalLoad`); its shape still moves an exempt load (`shape_series`);
- PVSystem and Generator elements: DER (`PVSystem.x`, `Generator.x`), rated P̄ = Pmpp or
  kW, S̄ = kVA, their snapshot output as the case's stored operating point.

Controls (RegControl, CapControl, SwtControl) act only through the states they settled;
meters (Monitor, EnergyMeter, Sensor) and protection (Fuse, Relay, Recloser) do not change
a snapshot. Any other element — or a load model, neutral impedance or generator model
opfbench cannot evaluate — is refused, naming its class, name and the file. A file
OpenDSS cannot compile is refused with OpenDSS's own message (file and line).

A RegControl's `debugtrace` (a diagnostic file OpenDSS would write beside the model) is
turned off. The voltage band is ANSI C84.1 Range A (0.95–1.05 p.u.) on 60 Hz circuits and EN 50160
(0.90–1.10 p.u.) on 50 Hz ones.

OpenDSS is one engine per process: reading holds a lock, and compiling never changes the
process's working folder (`AllowChangeDir(False)`).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from opfbench.errors import CaseFormatError, InputError, NetworkError
from opfbench.io.case import Case, CaseSeries
from opfbench.multiphase import GROUND, Branches, Element, Line, LoadModels, PhaseNetwork, Source, Transformer, Winding
from opfbench.multiphase.branches import LOAD_MODELS
from opfbench.multiphase.regulators import PT_MAX, PT_MIN, Regulator
from opfbench.network import DER

if TYPE_CHECKING:
    from opfbench.io.spec import CaseSpec

SOLVE_TOLERANCE = 1e-10
MIN_ITERATIONS = 100
ANSI_RANGE_A = ((0.95, 1.05), "ANSI C84.1 Range A")
EN_50160 = ((0.90, 1.10), "EN 50160")

_PD_KINDS = {"line": "line", "transformer": "transformer", "capacitor": "capacitor", "reactor": "reactor"}
_IGNORED = {
    "regcontrol": "its settled taps are the transformers'",
    "capcontrol": "its settled states are the capacitors'",
    "swtcontrol": "its settled states are the switches'",
    "monitor": "a meter",
    "energymeter": "a meter",
    "sensor": "a meter",
    "fuse": "protection",
    "relay": "protection",
    "recloser": "protection",
}
_READ = {"vsource", "load", "pvsystem", "generator"} | set(_PD_KINDS)
VARIABLE, FIXED, EXEMPT = 0, 1, 2  # OpenDSS's Load.status (`Loads.Status`): what load multipliers and shapes move
_LENGTH_KM = {1: 1.609344, 2: 0.3048, 3: 1.0, 4: 1e-3, 5: 3.048e-4, 6: 2.54e-5, 7: 1e-5, 8: 1e-6}  # OpenDSS LineUnits
_lock = threading.Lock()


@dataclass(frozen=True, eq=False)
class LoadShape:
    """An OpenDSS load shape: P and Q multipliers of the loads' nominal powers (Q: P's
    where the shape gives none), one every `interval_h` hours."""

    p: np.ndarray
    q: np.ndarray
    interval_h: float


@dataclass(frozen=True, eq=False)
class OpenDssCircuit:
    """What `read_opendss` returns: the network and the snapshot the file defines —
    per load P and Q (MW, MVAr), per DER P and Q (MW, MVAr, generated) — and notes; per
    load its shape's name ('' for none) and its OpenDSS status (VARIABLE, FIXED, EXEMPT),
    and the shapes."""

    network: PhaseNetwork
    load_p_mw: np.ndarray
    load_q_mvar: np.ndarray
    der_p_mw: np.ndarray
    der_q_mvar: np.ndarray
    notes: tuple[str, ...]
    load_shapes: tuple[str, ...] = ()
    shapes: dict[str, LoadShape] = field(default_factory=dict)
    load_status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))


def _dss():
    import opendssdirect as dss

    return dss


def _each(api) -> Iterator[None]:
    """Make each element of an OpenDSS collection (`dss.Lines`, `dss.Loads`, …) the active
    one in turn, in the circuit's order."""
    i = api.First()
    while i:
        yield
        i = api.Next()


def _complex(values) -> np.ndarray:
    return np.asarray(values, dtype=float).view(complex)


def read_opendss(path: str | Path, name: str | None = None, tap_control: bool = False) -> OpenDssCircuit:
    """Compile and solve the OpenDSS master file `path` and build its model (module
    docstring); `name` names the network (default: the circuit's own name); with
    `tap_control` also its RegControls, for the power flow to move their taps
    (`opfbench.multiphase.regulators`)."""
    path = Path(path)
    if not path.is_file():
        raise CaseFormatError(f"OpenDSS file {str(path)!r} not found")
    dss = _dss()
    with _lock:
        cwd = os.getcwd()
        try:
            dss.Basic.AllowChangeDir(False)
            dss.Text.Command("clear")
            try:
                dss.Text.Command(f'compile "{path.resolve()}"')
            except Exception as exc:  # noqa: BLE001 — DSSException: OpenDSS's own message, with file and line
                raise CaseFormatError(f"OpenDSS cannot compile {path}: {_message(exc)}") from None
            if not _has_circuit(dss):
                raise CaseFormatError(f"{path}: OpenDSS compiled it but it defines no circuit (New Circuit.NAME …)")
            try:
                return _Reader(dss, path, name, tap_control).read()
            except NetworkError as exc:  # the model's own checks (e.g. islanded nodes), named by the file
                raise CaseFormatError(f"{path}: {exc}") from None
        finally:
            os.chdir(cwd)


def _has_circuit(dss) -> bool:
    try:
        return bool(dss.Circuit.Name())
    except Exception:  # noqa: BLE001 — DSSException "There is no active circuit"
        return False


def _message(exc: Exception) -> str:
    args = tuple(getattr(exc, "args", ()))
    text = args[1] if len(args) == 2 and isinstance(args[1], str) else str(exc)
    return " ".join(text.split())


class _Reader:
    """One pass over the compiled, solved circuit."""

    def __init__(self, dss, path: Path, name: str | None, tap_control: bool = False) -> None:
        self.dss = dss
        self.path = path
        self.name = name
        self.tap_control = tap_control
        self.notes: list[str] = []
        self.load_shape: list[str] = []

    def refuse(self, element: str, problem: str) -> None:
        raise CaseFormatError(f"{self.path}: {element}: {problem}")

    def read(self) -> OpenDssCircuit:
        dss = self.dss
        self._check_classes()
        compiled_taps = self._compiled_taps() if self.tap_control else {}
        self._solve()
        self.node_names = [n.lower() for n in dss.Circuit.AllNodeNames()]
        self.bus_names = [b.lower() for b in dss.Circuit.AllBusNames()]
        bus_index = {b: i for i, b in enumerate(self.bus_names)}
        self.node_index = {n: i for i, n in enumerate(self.node_names)}
        node_bus = np.array([bus_index[n.rsplit(".", 1)[0]] for n in self.node_names], dtype=int)
        node_phase = np.array([int(n.rsplit(".", 1)[1]) for n in self.node_names], dtype=int)
        self.bus_index = bus_index
        kv = np.zeros(len(self.bus_names))
        for i in range(len(self.bus_names)):
            dss.Circuit.SetActiveBusi(i)
            kv[i] = dss.Bus.kVBase()
        elements, lines, transformers = self._elements()
        source = self._source()
        load_names, load_bus, load_p, load_q, models, load_br, load_status = self._loads()
        ders, der_names, der_br, der_p, der_q = self._ders()
        frequency = float(dss.Solution.Frequency())
        band, band_name = EN_50160 if abs(frequency - 50.0) < 1e-9 else ANSI_RANGE_A
        regulators = self._regulators(elements, compiled_taps) if self.tap_control else ()
        net = PhaseNetwork(
            self.name or dss.Circuit.Name(),
            frequency,
            tuple(self.bus_names),
            kv,
            node_bus,
            node_phase,
            tuple(elements),
            tuple(lines),
            tuple(transformers),
            source,
            tuple(load_names),
            load_bus,
            load_p,
            load_q,
            models,
            load_br,
            tuple(ders),
            tuple(der_names),
            der_br,
            band,
            band_name,
            regulators,
            self.tap_control,
            load_status != VARIABLE,
        )
        shapes = self._shapes()
        return OpenDssCircuit(net, load_p, load_q, der_p, der_q, tuple(self.notes), tuple(self.load_shape), shapes, load_status)

    def _shapes(self) -> dict[str, LoadShape]:
        """The load shapes the loads follow (their yearly shape, else their daily one)."""
        ls = self.dss.LoadShape
        out = {}
        for name in sorted(set(self.load_shape) - {""}):
            ls.Name(name)
            p = np.asarray(ls.PMult(), dtype=float)
            q = np.asarray(ls.QMult(), dtype=float)
            out[name] = LoadShape(p, q if q.shape == p.shape else p, float(ls.HrInterval()))
        return out

    # ----- regulators (taps=control) --------------------------------------------------
    def _compiled_taps(self) -> dict[str, float]:
        """The tap each RegControl's tap winding compiles to (before any solve), by
        RegControl name."""
        rc, t = self.dss.RegControls, self.dss.Transformers
        out = {}
        for _ in _each(rc):
            name = rc.Name().lower()
            t.Name(rc.Transformer())
            t.Wdg(rc.TapWinding())
            out[name] = float(t.Tap())
        return out

    def _regulators(self, elements: list[Element], compiled: dict[str, float]) -> tuple[Regulator, ...]:
        """Every enabled RegControl as a `Regulator`: its settings, and its transformer's
        primitive admittance at every tap position (OpenDSS's own, set tap by tap and put
        back at the settled one). A RegControl using what opfbench does not emulate is
        refused (`opfbench.multiphase.regulators`)."""
        dss = self.dss
        rc, t, run = dss.RegControls, dss.Transformers, dss.Text.Command
        index = {e.name.lower(): i for i, e in enumerate(elements)}
        settings = []
        for _ in _each(rc):
            name = rc.Name().lower()
            full = f"RegControl.{name}"
            if not dss.CktElement.Enabled():
                continue

            def prop(key: str, name: str = name) -> str:
                run(f"? regcontrol.{name}.{key}")
                return dss.Text.Result().strip().lower()

            unsupported = [
                what
                for what, used in (
                    ("reversible=yes", rc.IsReversible()),
                    ("cogen=yes", prop("cogen").startswith("y")),
                    ("a regulated bus (bus=)", bool(rc.MonitoredBus())),
                    ("vlimit", rc.VoltageLimit() > 0),
                    ("ldc_z", float(prop("ldc_z")) > 0),
                    ("inversetime=yes", rc.IsInverseTime()),
                )
                if used
            ]
            if unsupported:
                self.refuse(full, f"taps=control does not emulate {', '.join(unsupported)}; use the settled taps (taps=held)")
            transformer = f"transformer.{rc.Transformer().lower()}"
            if transformer not in index:
                self.refuse(full, f"its transformer {rc.Transformer()} is not an enabled element")
            phase_text = prop("ptphase")
            pt_phase = PT_MAX if phase_text.startswith("max") else PT_MIN if phase_text.startswith("min") else int(phase_text)
            t.Name(rc.Transformer())
            t.Wdg(rc.Winding())
            delta = bool(t.IsDelta())
            kv = float(t.kV())
            phases = int(elements[index[transformer]].nodes.shape[1]) - 1
            base_v = kv * 1e3 / (np.sqrt(3.0) if not delta and phases in (2, 3) else 1.0)
            t.Wdg(rc.TapWinding())
            fields = dict(
                name=name,
                element=index[transformer],
                winding=int(rc.Winding()),
                tap_winding=int(rc.TapWinding()),
                vreg=float(rc.ForwardVreg()),
                band=float(rc.ForwardBand()),
                pt_ratio=float(rc.PTRatio()),
                ct_rating=float(rc.CTPrimary()),
                r=float(rc.ForwardR()),
                x=float(rc.ForwardX()),
                pt_phase=pt_phase,
                delta=delta,
                delay=float(rc.Delay()),
                tap_limit=int(rc.MaxTapChange()),
                base_v=base_v,
            )
            settings.append((fields, compiled[name], float(t.Tap()), float(t.MinTap()), float(t.MaxTap()), int(t.NumTaps())))
        seen = [(f["element"], f["tap_winding"]) for f, *_ in settings]
        if len(set(seen)) != len(seen):
            self.refuse("RegControl", "two RegControls move the same winding's tap; taps=control needs one each")
        out = []
        for fields, compiled_tap, settled_tap, lo, hi, n_taps in settings:
            full = f"RegControl.{fields['name']}"
            increment = (hi - lo) / n_taps if n_taps > 0 else 0.0
            if increment <= 0:
                self.refuse(full, "its transformer has no tap range (NumTaps, MinTap, MaxTap)")
            k_lo = -int(np.ceil((compiled_tap - lo) / increment - 1e-9))
            k_hi = int(np.ceil((hi - compiled_tap) / increment - 1e-9))
            taps = np.clip(compiled_tap + np.arange(k_lo, k_hi + 1) * increment, lo, hi)
            settled = int(np.argmin(np.abs(taps - settled_tap)))
            if abs(taps[settled] - settled_tap) > 1e-9:
                self.refuse(full, f"settled tap {settled_tap!r} is off the tap grid through the compiled {compiled_tap!r}")
            el = elements[int(fields["element"])]
            yprims = self._tap_yprims(el.name, int(fields["tap_winding"]), taps, settled_tap, el.yprim.shape[0])
            out.append(Regulator(**fields, taps=taps, yprims=yprims, start=-k_lo, settled=settled))
        if out:
            self.notes.append(
                f"taps=control: {len(out)} regulator(s) move their taps in the power flow as OpenDSS's static RegControl "
                "does (time delays order the moves and delay nothing: a snapshot has no time)"
            )
        return tuple(out)

    def _tap_yprims(self, element: str, winding: int, taps: np.ndarray, settled: float, size: int) -> np.ndarray:
        """(n_pos, size, size) the transformer's primitive admittance at each tap of its
        winding `winding` (OpenDSS's, rebuilt at each), the settled tap put back after."""
        dss, run = self.dss, self.dss.Text.Command
        out = np.empty((len(taps), size, size), dtype=complex)
        short = element.split(".", 1)[1]
        for k, tap in enumerate([*taps.tolist(), settled]):
            run(f"transformer.{short}.wdg={winding} tap={tap!r}")
            dss.Solution.BuildYMatrix(0, False)
            if k < len(taps):
                dss.Circuit.SetActiveElement(element)
                out[k] = self._yprim(size)
        return out

    # ----- the compiled circuit ------------------------------------------------------
    def _check_classes(self) -> None:
        """Every element is of a class opfbench reads or may ignore (else refused)."""
        for full in self.dss.Circuit.AllElementNames():
            cls = full.split(".", 1)[0].lower()
            if cls not in _READ and cls not in _IGNORED:
                self.refuse(
                    full,
                    f"opfbench cannot model OpenDSS {full.split('.', 1)[0]} elements (it reads lines, transformers, "
                    "capacitors, reactors, one Vsource, loads, PVSystems and Generators; controls, meters and protection "
                    "act through the states they settle); remove or disable it",
                )

    def _solve(self) -> None:
        dss = self.dss
        run = dss.Text.Command
        if dss.RegControls.Count():
            run("batchedit regcontrol..* debugtrace=no")  # a diagnostic that writes a file beside the model
        run("set mode=snapshot")
        run(f"set tolerance={SOLVE_TOLERANCE!r}")
        if dss.Solution.MaxIterations() < MIN_ITERATIONS:
            dss.Solution.MaxIterations(MIN_ITERATIONS)
        try:
            dss.Solution.Solve()
        except Exception as exc:  # noqa: BLE001 — DSSException
            raise CaseFormatError(f"{self.path}: OpenDSS cannot solve its snapshot: {_message(exc)}") from None
        if not dss.Solution.Converged():
            raise CaseFormatError(
                f"{self.path}: OpenDSS's snapshot did not converge ({dss.Solution.Iterations()} iterations, "
                f"{dss.Solution.ControlIterations()} control iterations)"
            )

    def _terminal_nodes(self, full: str) -> tuple[tuple[int, ...], np.ndarray]:
        """(bus per terminal, nodes (terminals, conductors)) of the active element."""
        el = self.dss.CktElement
        n_t, n_c = el.NumTerminals(), el.NumConductors()
        order = np.asarray(el.NodeOrder(), dtype=int).reshape(n_t, n_c)
        buses = tuple(self.bus_index[b.split(".", 1)[0].lower()] for b in el.BusNames())
        nodes = np.full((n_t, n_c), GROUND, dtype=int)
        for t in range(n_t):
            for c in range(n_c):
                if order[t, c] != 0:
                    key = f"{self.bus_names[buses[t]]}.{order[t, c]}"
                    if key not in self.node_index:
                        self.refuse(full, f"terminal {t + 1} conductor {c + 1} is on node {key}, which OpenDSS has no node for")
                    nodes[t, c] = self.node_index[key]
        return buses, nodes

    def _yprim(self, size: int) -> np.ndarray:
        return _complex(self.dss.CktElement.YPrim()).reshape(size, size)

    def _elements(self) -> tuple[list[Element], list[Line], list[Transformer]]:
        dss = self.dss
        elements: list[Element] = []
        lines: list[Line] = []
        transformers: list[Transformer] = []
        regulated = set()
        for _ in _each(dss.RegControls):
            regulated.add(dss.RegControls.Transformer().lower())
        for cls, kind in (
            ("Lines", "line"),
            ("Transformers", "transformer"),
            ("Capacitors", "capacitor"),
            ("Reactors", "reactor"),
        ):
            api = getattr(dss, cls)
            for _ in _each(api):
                el = dss.CktElement
                full = el.Name()
                if el.Enabled():
                    buses, nodes = self._terminal_nodes(full)
                    y = self._yprim(nodes.size)
                    index = len(elements)
                    elements.append(Element(full, kind, buses, nodes, y))
                    if kind == "line":
                        lines.append(self._line(index, nodes, y))
                    elif kind == "transformer":
                        transformers.append(self._transformer(index, api.Name().lower() in regulated))
        return elements, lines, transformers

    def _line(self, index: int, nodes: np.ndarray, y: np.ndarray) -> Line:
        n = nodes.shape[1]
        series = -y[:n, n:]
        try:
            z = np.linalg.inv(series)
        except np.linalg.LinAlgError:
            z = np.full((n, n), np.nan + 0j)
        shunt = 2.0 * (y[:n, :n] - series)
        lines = self.dss.Lines
        length = lines.Length() * _LENGTH_KM.get(lines.Units(), np.nan)
        return Line(index, z, shunt, float(length), bool(lines.IsSwitch()))

    def _transformer(self, index: int, regulated: bool) -> Transformer:
        t = self.dss.Transformers
        windings = []
        for w in range(1, t.NumWindings() + 1):
            t.Wdg(w)
            windings.append(
                Winding(
                    "delta" if t.IsDelta() else "wye",
                    float(t.kV()),
                    float(t.kVA()),
                    float(t.Tap()),
                    float(t.R()),
                    float(t.MinTap()),
                    float(t.MaxTap()),
                    int(t.NumTaps()),
                )
            )
        x = (float(t.Xhl()),) if len(windings) == 2 else (float(t.Xhl()), float(t.Xht()), float(t.Xlt()))
        return Transformer(index, int(self.dss.CktElement.NumPhases()), tuple(windings), x, regulated)

    def _source(self) -> Source:
        dss = self.dss
        found = []
        for _ in _each(dss.Vsources):
            if dss.CktElement.Enabled():
                found.append(dss.CktElement.Name())
                full = dss.CktElement.Name()
                buses, nodes = self._terminal_nodes(full)
                if nodes.shape[0] > 1 and (nodes[1] != GROUND).any():
                    self.refuse(full, "a Vsource whose second terminal is not grounded (a series source) is not supported")
                n = nodes.shape[1]
                y = self._yprim(nodes.size)[:n, :n]
                phases = int(dss.Vsources.Phases())
                kv = dss.Vsources.BasekV() * dss.Vsources.PU()
                mag = kv * 1e3 / (np.sqrt(3.0) if phases > 1 else 1.0)
                angles = np.deg2rad(dss.Vsources.AngleDeg() - 120.0 * np.arange(n))
                keep = nodes[0] != GROUND
                source = Source(full, buses[0], nodes[0][keep], y[np.ix_(keep, keep)], (mag * np.exp(1j * angles))[keep])
        if len(found) != 1:
            raise CaseFormatError(
                f"{self.path}: opfbench models one source (Vsource); the circuit has {len(found)}: {', '.join(found) or 'none'}"
            )
        return source

    def _branches(self, full: str, nodes: np.ndarray, phases: int, delta: bool, kv: float) -> list[tuple[int, int, float]]:
        """(a, b, base V) of each branch of a load or DER whose terminal has `nodes`."""
        n_c = len(nodes)
        if delta:
            base = kv * 1e3
            pairs = [(i, (i + 1) % n_c) for i in range(phases)]
        else:
            if n_c != phases + 1:
                self.refuse(full, f"a wye element of {phases} phase(s) must have {phases + 1} conductors, it has {n_c}")
            base = kv * 1e3 / (np.sqrt(3.0) if phases in (2, 3) else 1.0)
            pairs = [(i, n_c - 1) for i in range(phases)]
        out = []
        for i, j in pairs:
            if nodes[i] == GROUND:
                self.refuse(full, f"conductor {i + 1} is connected to ground (node 0); a phase conductor must be on a node")
            out.append((int(nodes[i]), int(nodes[j]), base))
        return out

    def _loads(self):
        dss = self.dss
        loads = dss.Loads
        names, bus, p, q = [], [], [], []
        model, vmin, vmax, vlow, cvr_p, cvr_q, status = [], [], [], [], [], [], []
        owner, a, b, base, share = [], [], [], [], []
        for _ in _each(loads):
            el = dss.CktElement
            full = el.Name()
            if el.Enabled():
                buses, nodes = self._terminal_nodes(full)
                m = int(loads.Model())
                if m not in LOAD_MODELS:
                    self.refuse(
                        full,
                        f"OpenDSS load model {m}; opfbench evaluates " + ", ".join(f"{k} ({v})" for k, v in LOAD_MODELS.items()),
                    )
                delta = bool(loads.IsDelta())
                if not delta and (loads.Rneut() >= 0 or loads.Xneut() != 0):
                    self.refuse(full, "a neutral impedance (Rneut/Xneut) of a wye load is not supported")
                phases = int(el.NumPhases())
                branches = self._branches(full, nodes[0], phases, delta, float(loads.kV()))
                y = self._yprim(nodes.size)
                conductor = {int(n): c for c, n in enumerate(nodes[0])}
                first_a, first_b, first_base = branches[0]
                y_eq = (
                    -y[conductor[first_a], conductor[first_b]] if first_b != GROUND else -y[conductor[first_a], len(nodes[0]) - 1]
                )
                s_branch = np.conj(y_eq) * first_base**2  # W + j var per branch at the nominal (OpenDSS's Yeq)
                index = len(names)
                names.append(full)
                bus.append(buses[0])
                p.append(s_branch.real * phases / 1e6)
                q.append(s_branch.imag * phases / 1e6)
                model.append(m)
                vmin.append(loads.Vminpu())
                vmax.append(loads.Vmaxpu())
                dss.Text.Command(f"? {full}.vlowpu")
                vlow.append(float(dss.Text.Result()))
                cvr_p.append(loads.CVRwatts())
                cvr_q.append(loads.CVRvars())
                status.append(int(loads.Status()))
                self.load_shape.append((loads.Yearly() or loads.Daily()).lower())
                for br in branches:
                    owner.append(index)
                    a.append(br[0])
                    b.append(br[1])
                    base.append(br[2])
                    share.append(1.0 / phases)
        models = LoadModels(np.array(model, dtype=int), vmin, vmax, vlow, cvr_p, cvr_q)
        return (
            names,
            np.array(bus, dtype=int),
            np.array(p, dtype=float),
            np.array(q, dtype=float),
            models,
            Branches(owner, a, b, base, share, len(names)),
            np.array(status, dtype=int),
        )

    def _ders(self):
        dss = self.dss
        ders, names = [], []
        owner, a, b, base, share = [], [], [], [], []
        p_out, q_out = [], []
        for cls in ("PVsystems", "Generators"):
            api = getattr(dss, cls)
            for _ in _each(api):
                el = dss.CktElement
                full = el.Name()
                if el.Enabled():
                    buses, nodes = self._terminal_nodes(full)
                    phases = int(el.NumPhases())
                    if cls == "Generators":
                        if int(api.Model()) != 1:
                            self.refuse(
                                full, f"Generator model {api.Model()}; opfbench reads model 1 (constant P and Q) as a DER"
                            )
                        rating, s_rated, energy = api.kW() / 1e3, api.kva() / 1e3, "other"
                        delta = bool(api.IsDelta())
                        kv = float(api.kV())
                    else:
                        rating, s_rated, energy = api.Pmpp() / 1e3, api.kVARated() / 1e3, "solar"
                        dss.Text.Command(f"? {full}.conn")
                        delta = dss.Text.Result().strip().lower() in ("delta", "ll")
                        dss.Text.Command(f"? {full}.kv")
                        kv = float(dss.Text.Result())
                    if not rating > 0:
                        self.refuse(full, f"rated power {rating * 1e3:g} kW; a DER needs a positive rating")
                    powers = np.asarray(el.Powers(), dtype=float)
                    p_out.append(-powers[0::2].sum() / 1e3)
                    q_out.append(-powers[1::2].sum() / 1e3)
                    index = len(ders)
                    ders.append(DER(buses[0], "inverter", rating, max(s_rated, rating), energy))
                    names.append(full)
                    for br in self._branches(full, nodes[0], phases, delta, kv):
                        owner.append(index)
                        a.append(br[0])
                        b.append(br[1])
                        base.append(br[2])
                        share.append(1.0 / phases)
        p = np.clip(np.array(p_out, dtype=float), 0.0, [d.rating_mw for d in ders]) if ders else np.zeros(0)
        return ders, names, Branches(owner, a, b, base, share, len(ders)), p, np.array(q_out, dtype=float)


SHIPPED_SERIES = {
    "eulv": ("2016-06-28", "Europe/Berlin", "eulv's own 1-min load shapes (Daily_1min_100profiles) on the paper day"),
    "ckt24": (
        "2016-01-01",
        "Europe/Berlin",
        "ckt24's own 8760-h load shapes (LS_PhaseA/B/C, LS_ThreePhase, Other_Bus_Load) from 2016-01-01 00:00 local time",
    ),
}
"""The shipped feeders whose loads follow the file's own shapes in a study: the shapes'
first point at local midnight of the date, in the zone, and the series' source. eulv: the
paper day (`opfbench.data.PAPER_DAY` and `PAPER_DAY_TZ`); ckt24: its year of hourly
shapes on 2016 (the year of the PV profile) in the PV's own zone, so that load and PV
share one local clock (the shapes end on 2016-12-30, 2016 having 8784 hours)."""


def shape_series(circuit: OpenDssCircuit, start: str, tz: str, source: str) -> CaseSeries:
    """Every load on its own shape (its nominal P and Q × the shape's multipliers) from
    `start` in zone `tz` — a load of status `fixed` at its nominal throughout, as OpenDSS
    keeps it; the DER have no series of their own (a study runs them on the period's PV
    and wind profiles). CaseFormatError for a load without a shape or shapes of different
    lengths or steps."""
    names = sorted(circuit.shapes)
    fixed = circuit.load_status == FIXED
    if any(shape == "" and not still for shape, still in zip(circuit.load_shapes, fixed.tolist(), strict=True)) or not names:
        raise CaseFormatError(f"{source}: every load needs a yearly or daily load shape")
    shapes = [circuit.shapes[n] for n in names]
    if len({(len(sh.p), sh.interval_h) for sh in shapes}) != 1:
        raise CaseFormatError(f"{source}: the loads' shapes differ in length or step")
    n, step = len(shapes[0].p), shapes[0].interval_h
    index = pd.date_range(pd.Timestamp(start).tz_localize(tz), periods=n, freq=pd.Timedelta(hours=step))
    col = np.array(
        [len(names) if still else names.index(name) for name, still in zip(circuit.load_shapes, fixed.tolist(), strict=True)]
    )
    ones = np.ones((n, 1))  # the column of the fixed loads
    return CaseSeries(
        index,
        np.column_stack([*(sh.p for sh in shapes), ones]),
        col,
        circuit.load_p_mw,
        np.column_stack([*(sh.q for sh in shapes), ones]),
        col,
        circuit.load_q_mvar,
        np.zeros((n, 1)),
        np.zeros(0, dtype=int),
        np.zeros(0),
        source,
    )


NO_DER_NOTE = "the feeder has no DER (PVSystem or Generator elements): every strategy gives the no-action result"


def opendss_case(spec: CaseSpec, path: Path | None, name: str | None) -> Case:
    """The OpenDSS master file `path` — or, without it, the shipped feeder `name` (compiled
    from a temporary copy: `opfbench.cases.opendss_cases.opendss_copy`) — as a case: its
    three-phase network, and the snapshot the file defines as the stored operating point.
    Also kept on disk (`opfbench.io.disk_cache`): OpenDSS hands a large feeder over in
    seconds."""
    from opfbench.cases.opendss_cases import opendss_copy, opendss_master
    from opfbench.io.disk_cache import cached_case
    from opfbench.io.loading import file_stamp

    def build() -> Case:
        if path is None:
            assert name is not None
            with opendss_copy(name) as master:
                circuit = read_opendss(master, name, spec.taps == "control")
        else:
            circuit = read_opendss(path, name, spec.taps == "control")
        stored = (circuit.load_p_mw, circuit.load_q_mvar, circuit.der_p_mw, circuit.der_q_mvar)
        notes = circuit.notes if circuit.network.ders else circuit.notes + (NO_DER_NOTE,)
        series = None
        if path is None and name in SHIPPED_SERIES:
            series = shape_series(circuit, *SHIPPED_SERIES[name])
        return Case(spec.text, circuit.network, stored, series, notes=notes)

    record = path
    if record is None:
        assert name is not None
        record = opendss_master(name)
    return cached_case(spec.text, build, file_stamp(record, folder=True))


@dataclass(frozen=True)
class Placement:
    """A DER placed on a three-phase feeder: the bus (OpenDSS name), its phases (() = every
    phase of the bus), rated P̄ (MW), S̄ (MVA), kind and primary energy; `delta` a unit
    between its two phases (phase to phase) rather than from each phase to the neutral;
    `load` the load element it was placed beside (a placement rule on loads), if any."""

    bus: str
    phases: tuple[int, ...]
    rating_mw: float
    s_mva: float
    kind: str = "inverter"
    energy: str = "solar"
    delta: bool = False
    load: int | None = None


def place_ders(net: PhaseNetwork, placements: tuple[Placement, ...], what: str) -> PhaseNetwork:
    """`net` with the DER `placements` (a feeder without DER of its own): each a wye unit
    from its phases to the bus's neutral (its lowest neutral node; ground where the bus has
    none), single-phase on one phase, its P and Q split equally over several — or, `delta`,
    one unit between its two phases (base: the bus's phase-to-phase voltage); named
    `BUS.PHASES` (e.g. `675.1.2.3`; `-2`, `-3`, … for further units on the same phases). InputError naming `what` for a bus or phase that does
    not exist."""
    if net.ders:
        raise InputError(f"{what}: the feeder already has {len(net.ders)} DER of its own; der= places DER on a feeder without")
    bus_index = {b: i for i, b in enumerate(net.bus_names)}
    nodes_of: dict[int, dict[int, int]] = {}
    for i, (b, p) in enumerate(zip(net.node_bus.tolist(), net.node_phase.tolist(), strict=True)):
        nodes_of.setdefault(b, {})[p] = i
    ders: list[DER] = []
    names: list[str] = []
    owner, a, b_end, base, share = [], [], [], [], []
    for place in placements:
        bus = bus_index.get(place.bus)
        if bus is None:
            raise InputError(f"{what}: DER at bus {place.bus!r}: the feeder has no such bus")
        nodes = nodes_of.get(bus, {})
        present = tuple(p for p in (1, 2, 3) if p in nodes)
        phases = place.phases or present
        missing = [p for p in phases if p not in nodes]
        if missing or not phases:
            raise InputError(
                f"{what}: DER at bus {place.bus!r} phase {missing[0] if missing else '?'}: the bus has phases "
                f"{'.'.join(map(str, present)) or 'none'}"
            )
        neutral = min((p for p in nodes if p > 3), default=None)
        index = len(ders)
        name = stem = ".".join([place.bus, *map(str, phases)])
        for n in range(2, len(placements) + 2):
            if name not in names:
                break
            name = f"{stem}-{n}"  # a further unit on the same bus and phases
        ders.append(DER(bus, place.kind, place.rating_mw, place.s_mva, place.energy, name))  # type: ignore[arg-type]
        names.append(name)
        if place.delta:
            if len(phases) != 2:
                raise InputError(f"{what}: a phase-to-phase DER at bus {place.bus!r} needs two phases, got {len(phases)}")
            owner.append(index)
            a.append(nodes[phases[0]])
            b_end.append(nodes[phases[1]])
            base.append(net.bus_kv_ln[bus] * 1e3 * np.sqrt(3.0))
            share.append(1.0)
            continue
        for p in phases:
            owner.append(index)
            a.append(nodes[p])
            b_end.append(GROUND if neutral is None else nodes[neutral])
            base.append(net.bus_kv_ln[bus] * 1e3)
            share.append(1.0 / len(phases))
    branches = Branches(np.array(owner), np.array(a), np.array(b_end), np.array(base), np.array(share), len(ders))
    return replace(net, ders=tuple(ders), der_names=tuple(names), der_branches=branches)


def with_ders(case: Case, spec: CaseSpec, der_pf: float) -> Case:
    """A three-phase `case` with the DER of the spec's `der=` list (DerEntry with phases;
    generic inverters S̄ = P̄/`der_pf`, PV and DFIG S̄ = P̄), or — without one — its shipped
    placement rule (`opfbench.cases.opendss_pv.SHIPPED_PLACEMENTS`); the stored point has
    the placed DER at P = Q = 0."""
    from opfbench.cases.opendss_pv import SHIPPED_PLACEMENTS
    from opfbench.io.spec import parse_der_list

    net = case.network
    assert isinstance(net, PhaseNetwork)
    if spec.der is not None:
        placements = tuple(
            Placement(
                str(e.bus), e.phases, e.rating_mw, e.rating_mw / der_pf if e.kind == "inverter" else e.rating_mw, e.kind, e.energy
            )
            for e in parse_der_list(spec.der, spec.text, phased=True)
        )
    elif spec.source in SHIPPED_PLACEMENTS and not net.ders:
        placements = SHIPPED_PLACEMENTS[spec.source].place(net)
    else:
        return case
    placed = place_ders(net, placements, f"case {spec.text!r}")
    stored = case.stored
    if stored is not None:
        zeros = np.zeros(len(placed.ders))
        stored = (stored[0], stored[1], zeros, zeros)
    rule = "der=" if spec.der is not None else f"the shipped placement rule: {SHIPPED_PLACEMENTS[spec.source].text}"
    note = f"{len(placed.ders)} DER placed ({rule})"
    return replace(case, network=placed, stored=stored, notes=tuple(n for n in case.notes if n != NO_DER_NOTE) + (note,))
